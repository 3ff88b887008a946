"""
Scenario files: reading and checking them into a Scenario (pure, no ROS).

A scenario is a repeatable run of the simulated robot with a pass/fail verdict. One
scenario per YAML file; metres, seconds and radians; poses and goals in the map frame
(REP-103: x east, y north, yaw counter-clockwise; REP-105 frames)::

    scenario:
      name: apartment_tour             # required, [A-Za-z0-9_-]+
      description: 'Visits every room' # optional
      world: apartment                 # installed world name, or a path relative to this file
      map: apartment                   # optional: localisation map (default: the world's name)
      spawn: {x: 2.95, y: 2.0, yaw: 0.0}          # optional: default the world's robot_start
      initial_pose: {x: 2.95, y: 2.0, yaw: 0.0}   # optional: told to localisation; default spawn
      floor_friction_coefficient: 0.0  # optional, >= 0 (0: the robot's own wheel friction)
      sensor_noise_scale: 1.0          # optional, >= 0: times the simulator's lidar and IMU
                                       # noise (0: noiseless sensors)
      board: core                      # optional: core (the firmware's core in the
                                       # simulator) or firmware (main.py as flashed)
      real_time_factor: 1.0            # optional, > 0
      seed: 0                          # optional int >= 0
      authorised_zone: [[0.1, 0.1], [9.9, 0.1], [9.9, 7.9], [0.1, 7.9]]
                                       # optional: default the world's test_zone; [] = none;
                                       # or {include: [...], exclude: [[...], ...]}
                                       # (mecanum_safety.zone's format)
      moving_obstacles: []             # optional, extra ones in the world file's format
      steps:                           # required, at least one, run in order
      - goal: {x: 5.1, y: 6.2, yaw: 0.0, timeout_s: 90}    # NavigateToPose; expect reached
      - goal: {x: 12.0, y: 3.0, expect: refused, error: GOAL_OUTSIDE_ZONE}
      - waypoints:                     # Nav2's FollowWaypoints: every pose must be reached
          poses: [{x: 3.5, y: 1.5}, {x: 5.1, y: 6.2, yaw: 1.57}]
          timeout_s: 150               # optional: default 120 s per pose
      - command: 'forward 1.5 m'       # a robot_controller text command
        timeout_s: 20                  # optional: default the motion's duration + 10 s
        expect: done                   # optional: done (default) | stopped (the command
                                       # chain stopped it short) | rejected | any
      - cmd_vel: {vx: 0.3, vy: 0.0, wz: 0.0, duration_s: 3.0, source: scenario}
                                       # a body twist on a command source's topic
                                       # (twist_mux.yaml: scenario, teleop_keyboard,
                                       # joystick, external, ...), through the command chain
      - freeze: {node: amcl, duration_s: 5.0}   # the node's process hangs (SIGSTOP)
      - fault: {kind: lidar_blinded, onset_s: 2.0, duration_s: 5.0}
                                       # a fault (robot_simulation.faults: kind, onset_s
                                       # from this step's start, default 0; duration_s,
                                       # default null: to the end; the kind's parameters);
                                       # the step ends at once, the fault acts meanwhile
      - wait: {duration_s: 2.0}
      criteria:                        # all optional; defaults shown
        max_duration_s: null           # simulated seconds from the first step to the last
        no_collision: true
        stay_in_zone: true             # the footprint (ground truth) inside the zone
        max_localization_error_m: null # |estimate - truth| in x, y, at every estimate
        fault_reactions: false         # each injected fault's expected reaction
                                       # (mecanum_bringup.fault_reactions)
      expect: pass                     # pass | fail: the verdict this scenario must get

Goal ``expect``: ``reached`` (default), ``refused`` (the goal must end with the error code
``error``, a NavigateToPose result code name, or with any non-zero code when ``error`` is
not given) or ``any``. Command texts are checked with robot_controller's parser at load
time, cmd_vel twists against the robot's limits in motor_params.yaml, faults with
robot_simulation.faults' parse_fault.

:func:`load_scenario` raises :class:`ScenarioError` naming the file and the key, e.g.
``tour.yaml: steps[3].goal.yaw: must be a number, not 'north'`` (list indices count from
0, as in the file). The world is checked by building the scenario's world
(:func:`scenario_world_document`, the base world with robot_start = spawn, test_zone =
authorised_zone and the extra moving obstacles) with robot_simulation's loader, so the
spawn must be inside the world, in free space and at least 0.25 m from every obstacle.

The :class:`~mecanum_bringup.scenario_model.Scenario` and its steps are in
:mod:`mecanum_bringup.scenario_model`; runs are judged by
:mod:`mecanum_bringup.scenario_judge`.
"""

import copy
import functools
import math
from pathlib import Path
import re
import tempfile
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

from mecanum_bringup.scenario_model import (
    CmdVelStep, COMMAND_EXPECTATIONS, CommandStep, Criteria, DEFAULT_GOAL_TIMEOUT_S,
    FaultStep, FreezeStep, GOAL_EXPECTATIONS, GoalStep, NAVIGATE_TO_POSE_ERRORS, Pose,
    Scenario, Step, STEP_KINDS, VERDICTS, WaitStep, WaypointsStep)
from mecanum_control.robot_config import default_config_path, load_robot_config, RobotConfig
from mecanum_control.yaml_files import DocumentChecker, load_yaml_file, SAFE_LOADER
from mecanum_map_server.map_io import find_map_file, MapError
from mecanum_safety.zone import parse_zone, Zone, ZoneError
from robot_controller.command_parser import CommandError, CommandLimits, parse_command
from robot_simulation.faults import FaultError, parse_fault
from robot_simulation.simulator import BOARDS
from robot_simulation.world import find_world, load_world, World, WorldError
import yaml

PathLike = Union[str, Path]

#: A command step's default timeout is the motion's duration plus this (s).
COMMAND_TIMEOUT_MARGIN_S = 10.0
SCENARIO_KEYS = ('name', 'description', 'world', 'map', 'spawn', 'initial_pose',
                 'floor_friction_coefficient', 'sensor_noise_scale', 'board', 'real_time_factor',
                 'seed',
                 'authorised_zone', 'moving_obstacles', 'steps', 'criteria', 'expect')
CRITERIA_KEYS = ('max_duration_s', 'no_collision', 'stay_in_zone', 'max_localization_error_m',
                 'fault_reactions')


class ScenarioError(ValueError):
    """A malformed scenario file; the message names the file and the key."""


def find_scenarios(path_or_folder: PathLike) -> List[Path]:
    """Return [file] for a file, or the sorted *.yaml files of a folder."""
    path = Path(path_or_folder).expanduser()
    if path.is_file():
        return [path]
    if path.is_dir():
        return sorted(p for p in path.glob('*.yaml') if p.is_file())
    raise ScenarioError(f'{path}: no such scenario file or folder')


def load_scenario(path: PathLike) -> Scenario:
    """Read and check a scenario file; raise ScenarioError naming the file and the key."""
    path = Path(path)
    doc = load_yaml_file(path, 'scenario file', ScenarioError)
    return _Parser(path).parse(doc)


def parse_steps(steps: Any, source: PathLike) -> Tuple[Step, ...]:
    """
    Check a scenario's ``steps`` list alone (no world needed); return its Steps.

    source names the file in errors (ScenarioError, as load_scenario raises).
    """
    return _Parser(Path(source)).steps(steps)


def scenario_world_document(scenario: Scenario) -> Dict[str, Any]:
    """
    Return the scenario's world file document, for the simulator.

    It is the base world file's content with name kept, robot_start = spawn, test_zone =
    authorised_zone (left out when there is none), the scenario's moving_obstacles
    appended and a relative map path made absolute, so it can be written anywhere.
    """
    return _world_document(scenario.world_file, scenario.spawn, scenario.authorised_zone,
                           scenario.moving_obstacles)


def build_world(document: Dict[str, Any], file_name: str = 'world.yaml') -> World:
    """Load a world document through robot_simulation's loader (via a temporary file)."""
    with tempfile.TemporaryDirectory(prefix='scenario_world_') as directory:
        path = Path(directory) / file_name
        path.write_text(yaml.safe_dump(document, sort_keys=False), encoding='utf-8')
        return load_world(path)


def _world_document(world_file: Path, spawn: Pose, zone: Optional[Zone],
                    moving: Sequence[Dict[str, Any]]) -> Dict[str, Any]:
    world = copy.deepcopy(_world_file_document(world_file)['world'])
    world.setdefault('name', world_file.stem)
    x, y, yaw = spawn
    world['robot_start'] = {'x_m': float(x), 'y_m': float(y),
                            'yaw_deg': math.degrees(float(yaw))}
    if zone is None:
        world.pop('test_zone', None)
    else:
        world['test_zone'] = zone.to_document()
    world['moving_obstacles'] = list(world.get('moving_obstacles') or []) + [
        copy.deepcopy(dict(item)) for item in moving]
    map_value = world.get('map')
    if isinstance(map_value, str) and not map_value.startswith('package://'):
        map_path = Path(map_value).expanduser()
        if not map_path.is_absolute():
            world['map'] = str((world_file.parent / map_path).resolve())
    return {'world': world}


@functools.lru_cache(maxsize=1)
def command_sources() -> Dict[str, str]:
    """Return {source name: topic} of the command chain's twist_mux (config/twist_mux.yaml)."""
    from ament_index_python.packages import get_package_share_directory
    path = Path(get_package_share_directory('mecanum_safety')) / 'config' / 'twist_mux.yaml'
    params = yaml.safe_load(path.read_text(encoding='utf-8'))['twist_mux']['ros__parameters']
    return {name: str(entry['topic']) for name, entry in params['topics'].items()}


@functools.lru_cache(maxsize=1)
def _robot_config() -> RobotConfig:
    return load_robot_config(default_config_path())


def _file_key(path: Path) -> Tuple[str, int, int]:
    stat = path.stat()
    return str(path.resolve()), stat.st_mtime_ns, stat.st_size


@functools.lru_cache(maxsize=16)
def _cached_world(key: Tuple[str, int, int]) -> World:
    return load_world(Path(key[0]))


@functools.lru_cache(maxsize=16)
def _cached_document(key: Tuple[str, int, int]) -> Dict[str, Any]:
    return yaml.load(Path(key[0]).read_text(encoding='utf-8'), Loader=SAFE_LOADER)


def _base_world(world_file: Path) -> World:
    """Return the loaded world file (cached while the file is unchanged)."""
    return _cached_world(_file_key(world_file))


def _world_file_document(world_file: Path) -> Dict[str, Any]:
    """Return the world file's YAML document (cached while the file is unchanged)."""
    return _cached_document(_file_key(world_file))


class _Parser(DocumentChecker):
    """Checks one scenario document; every failure names the file and the key."""

    def __init__(self, path: Path):
        super().__init__(ScenarioError, path.name, top_key='scenario')
        self.path = path

    def pose(self, value: Any, key: str) -> Pose:
        """Return (x, y, yaw) from {x, y, yaw} (yaw optional, 0)."""
        raw = self.mapping(value, key, ('x', 'y'), ('yaw',))
        return (self.number(raw['x'], f'{key}.x'), self.number(raw['y'], f'{key}.y'),
                self.number(raw.get('yaw', 0.0), f'{key}.yaw'))

    def parse(self, doc: Any) -> Scenario:
        """Check the whole document and return the Scenario."""
        raw = self.mapping(self.document(doc, 'scenario'), '', ('name', 'world', 'steps'),
                           [k for k in SCENARIO_KEYS if k not in ('name', 'world', 'steps')])
        name = self.identifier(raw['name'], 'name')
        description = raw.get('description', '')
        if description is None:
            description = ''
        if not isinstance(description, str):
            self.fail('description', f'must be a string, not {description!r}')
        world_file = self.world_file(raw['world'])
        try:
            base = _base_world(world_file)
        except WorldError as error:
            self.fail('world', str(error))
        map_value = self.map_name(raw.get('map', base.name))
        spawn = self.pose(raw['spawn'], 'spawn') if 'spawn' in raw else base.robot_start
        initial_pose = (self.pose(raw['initial_pose'], 'initial_pose')
                        if 'initial_pose' in raw else spawn)
        friction = self.number(raw.get('floor_friction_coefficient', 0.0),
                               'floor_friction_coefficient', minimum=0.0)
        noise_scale = self.number(raw.get('sensor_noise_scale', 1.0), 'sensor_noise_scale',
                                  minimum=0.0)
        board = self.choice(raw.get('board', 'core'), 'board', BOARDS)
        real_time_factor = self.positive(raw.get('real_time_factor', 1.0), 'real_time_factor')
        seed = self.integer(raw.get('seed', 0), 'seed', 0)
        if 'authorised_zone' in raw and raw['authorised_zone'] is not None:
            try:
                zone = parse_zone(raw['authorised_zone'], 'authorised_zone')
            except ZoneError as error:
                self.fail('', str(error))
        else:
            zone = base.test_zone
        moving = self.moving_obstacles(raw.get('moving_obstacles'))
        steps = self.steps(raw['steps'])
        criteria = self.criteria(raw.get('criteria'))
        expect = self.choice(raw.get('expect', 'pass'), 'expect', VERDICTS)
        # Last, as it is the slow part: the world with this spawn, zone and obstacles.
        if spawn == base.robot_start and zone == base.test_zone and not moving:
            world = base
        else:
            world = self.scenario_world(world_file, base, spawn, zone, moving)
        return Scenario(
            name=name, source=self.path, world_file=world_file, map_name=map_value,
            spawn=spawn, initial_pose=initial_pose, steps=steps, description=description,
            floor_friction_coefficient=friction, sensor_noise_scale=noise_scale,
            board=board, real_time_factor=real_time_factor,
            seed=seed, authorised_zone=zone, moving_obstacles=moving, criteria=criteria,
            expect=expect, world=world)

    def world_file(self, value: Any) -> Path:
        """Return the world file: a path relative to the scenario file, or a world name."""
        text = self.text(value, 'world')
        candidate = Path(text).expanduser()
        if not candidate.is_absolute():
            candidate = self.path.parent / candidate
        if candidate.is_file():
            return candidate.resolve()
        if '/' in text or Path(text).suffix in ('.yaml', '.yml'):
            self.fail('world', f'no world file {text!r} (looked for {candidate})')
        try:
            return find_world(text)
        except WorldError as error:
            self.fail('world', str(error))

    def map_name(self, value: Any) -> str:
        """Return a map name, or a map file path made absolute; check that it exists."""
        text = self.text(value, 'map').strip()
        if text.startswith('package://') or ('/' not in text and not Path(text).suffix):
            try:
                find_map_file(text)
            except MapError as error:
                self.fail('map', f"{error} (the default is the world's name)")
            return text
        path = Path(text).expanduser()
        if not path.is_absolute():
            path = self.path.parent / path
        if not path.is_file():
            self.fail('map', f'no map file {text!r} (looked for {path})')
        return str(path.resolve())

    def moving_obstacles(self, value: Any) -> Tuple[Dict[str, Any], ...]:
        """Return the extra moving obstacles (checked later by building the world)."""
        if value is None:
            return ()
        if not isinstance(value, list):
            self.fail('moving_obstacles', f'must be a list, not {value!r}')
        for index, item in enumerate(value):
            if not isinstance(item, dict):
                self.fail(f'moving_obstacles[{index}]',
                          f'must be a mapping (name, radius_m, speed_m_s, path, loop), '
                          f'not {item!r}')
        return tuple(value)

    def scenario_world(self, world_file: Path, base: World, spawn: Pose,
                       zone: Optional[Zone],
                       moving: Tuple[Dict[str, Any], ...]) -> World:
        """Build the scenario's world; report its errors with the scenario's keys."""
        document = _world_document(world_file, spawn, zone, moving)
        label = world_file.name
        try:
            return build_world(document, label)
        except WorldError as error:
            message = str(error)
            if message.startswith(label + ': '):
                message = message[len(label) + 2:]
            self.fail(*_scenario_key(message, len(base.moving_obstacles)))

    def steps(self, value: Any) -> Tuple[Step, ...]:
        """Return the steps: a non-empty list."""
        if not isinstance(value, list) or not value:
            self.fail('steps', f'must be a non-empty list of steps, not {value!r}')
        return tuple(self.step(item, f'steps[{index}]') for index, item in enumerate(value))

    def step(self, raw: Any, key: str) -> Step:
        """Return one step: exactly one of STEP_KINDS."""
        if not isinstance(raw, dict):
            self.fail(key, f'must be a mapping with one of {", ".join(STEP_KINDS)}, '
                      f'not {raw!r}')
        kinds = [kind for kind in STEP_KINDS if kind in raw]
        if len(kinds) != 1:
            self.fail(key, f'needs exactly one of {", ".join(STEP_KINDS)}, got '
                      f'{", ".join(kinds) or "none"}')
        kind = kinds[0]
        self.mapping(raw, key, (kind,), ('timeout_s', 'expect') if kind == 'command' else ())
        where = f'{key}.{kind}'
        if kind == 'goal':
            return self.goal(raw['goal'], where)
        if kind == 'waypoints':
            return self.waypoints(raw['waypoints'], where)
        if kind == 'command':
            return self.command(raw, key)
        if kind == 'cmd_vel':
            return self.cmd_vel(raw['cmd_vel'], where)
        if kind == 'freeze':
            item = self.mapping(raw['freeze'], where, ('node', 'duration_s'))
            return FreezeStep(self.text(item['node'], f'{where}.node'),
                              self.positive(item['duration_s'], f'{where}.duration_s'))
        if kind == 'fault':
            return self.fault(raw['fault'], where)
        item = self.mapping(raw['wait'], where, ('duration_s',))
        return WaitStep(self.positive(item['duration_s'], f'{where}.duration_s'))

    def goal(self, value: Any, key: str) -> GoalStep:
        """Return a goal step."""
        raw = self.mapping(value, key, ('x', 'y'), ('yaw', 'timeout_s', 'expect', 'error'))
        expect = self.choice(raw.get('expect', 'reached'), f'{key}.expect', GOAL_EXPECTATIONS)
        error = raw.get('error')
        if error is not None:
            if expect != 'refused':
                self.fail(f'{key}.error', 'is only allowed with expect: refused')
            codes = [n for n in NAVIGATE_TO_POSE_ERRORS if n != 'NONE']
            if not isinstance(error, str) or error not in codes:
                self.fail(f'{key}.error', f'must be a NavigateToPose error code, one of '
                          f'{", ".join(codes)}; not {error!r}')
        return GoalStep(
            x=self.number(raw['x'], f'{key}.x'), y=self.number(raw['y'], f'{key}.y'),
            yaw=self.number(raw.get('yaw', 0.0), f'{key}.yaw'),
            timeout_s=self.positive(raw.get('timeout_s', DEFAULT_GOAL_TIMEOUT_S),
                                    f'{key}.timeout_s'),
            expect=expect, error=error)

    def waypoints(self, value: Any, key: str) -> WaypointsStep:
        """Return a waypoints step: a non-empty list of poses, timeout 120 s per pose."""
        raw = self.mapping(value, key, ('poses',), ('timeout_s',))
        poses = raw['poses']
        if not isinstance(poses, list) or not poses:
            self.fail(f'{key}.poses', f'must be a non-empty list of poses {{x, y, yaw}}, '
                      f'not {poses!r}')
        parsed = tuple(self.pose(pose, f'{key}.poses[{index}]')
                       for index, pose in enumerate(poses))
        timeout = raw.get('timeout_s', DEFAULT_GOAL_TIMEOUT_S * len(parsed))
        return WaypointsStep(parsed, self.positive(timeout, f'{key}.timeout_s'))

    def command(self, raw: Dict[str, Any], key: str) -> CommandStep:
        """Return a command step; the text must parse with robot_controller's grammar."""
        text = raw['command']
        if not isinstance(text, str) or not text.strip():
            self.fail(f'{key}.command', f'must be a text command, not {text!r}')
        try:
            motion = parse_command(text, CommandLimits())
        except CommandError as error:
            self.fail(f'{key}.command', f'{text!r}: {error}')
        timeout = raw.get('timeout_s', motion.duration_s + COMMAND_TIMEOUT_MARGIN_S)
        expect = self.choice(raw.get('expect', 'done'), f'{key}.expect',
                             COMMAND_EXPECTATIONS)
        return CommandStep(text.strip(), self.positive(timeout, f'{key}.timeout_s'), motion,
                           expect)

    def cmd_vel(self, value: Any, key: str) -> CmdVelStep:
        """Return a cmd_vel step within the robot's velocity limits (motor_params.yaml)."""
        raw = self.mapping(value, key, ('duration_s',), ('vx', 'vy', 'wz', 'source'))
        sources = command_sources()
        source = self.choice(raw.get('source', 'scenario'), f'{key}.source', sorted(sources))
        robot = _robot_config()
        limits = {'vx': ('max_velocity_x_m_s', robot.max_velocity_x_m_s),
                  'vy': ('max_velocity_y_m_s', robot.max_velocity_y_m_s),
                  'wz': ('max_angular_velocity_rad_s', robot.max_angular_velocity_rad_s)}
        twist = {}
        for name, (limit_name, limit) in limits.items():
            twist[name] = self.number(raw.get(name, 0.0), f'{key}.{name}')
            if abs(twist[name]) > limit:
                self.fail(f'{key}.{name}', f"{twist[name]:g} exceeds the robot's "
                          f'{limit_name} {limit:g} (motor_params.yaml)')
        return CmdVelStep(twist['vx'], twist['vy'], twist['wz'],
                          self.positive(raw['duration_s'], f'{key}.duration_s'),
                          source, sources[source])

    def fault(self, value: Any, key: str) -> FaultStep:
        """Return a fault step, checked by robot_simulation's parse_fault."""
        try:
            return FaultStep(parse_fault(value, key))
        except FaultError as error:
            # parse_fault says 'KEY: MESSAGE' with KEY inside key: fail at that key.
            where, _, message = str(error).partition(': ')
            self.fail(where, message)

    def criteria(self, value: Any) -> Criteria:
        """Return the Criteria; every key is optional."""
        if value is None:
            return Criteria()
        raw = self.mapping(value, 'criteria', (), CRITERIA_KEYS)
        defaults = Criteria()
        return Criteria(
            max_duration_s=self.optional_positive(
                raw.get('max_duration_s', defaults.max_duration_s), 'criteria.max_duration_s'),
            no_collision=self.boolean(raw.get('no_collision', defaults.no_collision),
                                      'criteria.no_collision'),
            stay_in_zone=self.boolean(raw.get('stay_in_zone', defaults.stay_in_zone),
                                      'criteria.stay_in_zone'),
            max_localization_error_m=self.optional_positive(
                raw.get('max_localization_error_m', defaults.max_localization_error_m),
                'criteria.max_localization_error_m'),
            fault_reactions=self.boolean(raw.get('fault_reactions', defaults.fault_reactions),
                                         'criteria.fault_reactions'))


#: A world message about a moving obstacle: index, ' name' (if any), .key (if any), message.
_MOVING = re.compile(r"^moving_obstacles\[(\d+)\]((?: '[^']*')?)((?:\.[^ :]+)?): (.*)$",
                     re.DOTALL)


def _scenario_key(world_message: str, base_moving: int) -> Tuple[str, str]:
    """Map a world loader message (without the file label) to (scenario key, message)."""
    if world_message.startswith('robot_start: '):
        message = world_message[len('robot_start: '):]
        return 'spawn', message.replace('the test_zone', 'the authorised_zone')
    if world_message.startswith('test_zone: '):
        return 'authorised_zone', world_message[len('test_zone: '):]
    match = _MOVING.match(world_message)
    if match:
        index, name, key, message = int(match.group(1)), *match.group(2, 3, 4)
        if index >= base_moving:
            named = f'{name.strip()}: ' if name and not key else ''
            return f'moving_obstacles[{index - base_moving}]{key}', named + message
        return 'spawn', f"the world's moving obstacle{name}{key}: {message}"
    return 'world', world_message
