"""
Scenario files and the judging of scenario runs (pure, no ROS).

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
      - wait: {duration_s: 2.0}
      criteria:                        # all optional; defaults shown
        max_duration_s: null           # simulated seconds from the first step to the last
        no_collision: true
        stay_in_zone: true             # the robot's centre (ground truth) inside the zone
        max_localization_error_m: null # |estimate - truth| in x, y, at every estimate
      expect: pass                     # pass | fail: the verdict this scenario must get

Goal ``expect``: ``reached`` (default), ``refused`` (the goal must end with the error code
``error``, a NavigateToPose result code name, or with any non-zero code when ``error`` is
not given) or ``any``. Command texts are checked with robot_controller's parser at load
time, cmd_vel twists against the robot's limits in motor_params.yaml.

:func:`load_scenario` raises :class:`ScenarioError` naming the file and the key, e.g.
``tour.yaml: steps[3].goal.yaw: must be a number, not 'north'`` (list indices count from
0, as in the file). The world is checked by building the scenario's world
(:func:`scenario_world_document`, the base world with robot_start = spawn, test_zone =
authorised_zone and the extra moving obstacles) with robot_simulation's loader, so the
spawn must be inside the world, in free space and at least 0.25 m from every obstacle.

:func:`judge` turns a :class:`RunRecord` (what the runner recorded) into a
:class:`Verdict`: one :class:`CriterionResult` per step (``step 1`` is ``steps[0]``) and
per enabled criterion; the verdict is 'pass' when every one passed.
"""

import copy
from dataclasses import dataclass, field
import functools
import math
from pathlib import Path
import re
import tempfile
from typing import Any, Dict, List, NoReturn, Optional, Sequence, Tuple, Union

from mecanum_control.robot_config import default_config_path, load_robot_config, RobotConfig
from mecanum_control.yaml_files import load_yaml_file, SAFE_LOADER
from mecanum_map_server.map_io import find_map_file, MapError
from mecanum_safety.zone import parse_zone, Zone, ZoneError
import numpy as np
from robot_controller.command_parser import CommandError, CommandLimits, Motion, parse_command
from robot_simulation.world import (
    find_world, load_world, World, WorldError)
import yaml

PathLike = Union[str, Path]
Point = Tuple[float, float]
Pose = Tuple[float, float, float]

#: NavigateToPose result codes (error_code of nav2_msgs' NavigateToPose result, the
#: navigator's values: mecanum_navigation.navigator.navigator); test_scenario checks this table
#: against them.
NAVIGATE_TO_POSE_ERRORS: Dict[str, int] = {
    'NONE': 0,
    'UNKNOWN': 9000,
    'FAILED_TO_LOAD_BEHAVIOR_TREE': 9001,
    'TF_ERROR': 9002,
    'TIMEOUT': 9003,
    'GOAL_OUTSIDE_ZONE': 9100,
    'GOAL_IN_OBSTACLE': 9101,
    'GOAL_OUTSIDE_MAP': 9102,
    'NO_VALID_PATH': 9103,
    'STUCK': 9104,
    'CANCELED': 9105,
    'PREEMPTED': 9106,
    'INVALID_GOAL': 9107,
}
ERROR_NAMES: Dict[int, str] = {code: name for name, code in NAVIGATE_TO_POSE_ERRORS.items()}

#: Default goal timeout (simulated s).
DEFAULT_GOAL_TIMEOUT_S = 120.0
#: A command step's default timeout is the motion's duration plus this (s).
COMMAND_TIMEOUT_MARGIN_S = 10.0

GOAL_EXPECTATIONS = ('reached', 'refused', 'any')
VERDICTS = ('pass', 'fail')
STEP_KINDS = ('goal', 'waypoints', 'command', 'cmd_vel', 'wait', 'freeze')
COMMAND_EXPECTATIONS = ('done', 'stopped', 'rejected', 'any')
SCENARIO_KEYS = ('name', 'description', 'world', 'map', 'spawn', 'initial_pose',
                 'floor_friction_coefficient', 'sensor_noise_scale', 'real_time_factor', 'seed',
                 'authorised_zone', 'moving_obstacles', 'steps', 'criteria', 'expect')
CRITERIA_KEYS = ('max_duration_s', 'no_collision', 'stay_in_zone', 'max_localization_error_m')
_NAME = re.compile(r'[A-Za-z0-9_-]+')


class ScenarioError(ValueError):
    """A malformed scenario file; the message names the file and the key."""


@dataclass(frozen=True)
class GoalStep:
    """Navigate to (x, y, yaw) in the map frame (m, rad) within timeout_s (simulated s)."""

    x: float
    y: float
    yaw: float = 0.0
    timeout_s: float = DEFAULT_GOAL_TIMEOUT_S
    expect: str = 'reached'
    error: Optional[str] = None  # expected result code name when expect == 'refused'

    kind = 'goal'

    @property
    def error_code(self) -> Optional[int]:
        """Return the expected NavigateToPose result code, or None for any non-zero one."""
        return None if self.error is None else NAVIGATE_TO_POSE_ERRORS[self.error]

    def describe(self) -> str:
        """Return e.g. 'goal (5.10, 6.20)'."""
        return f'goal ({self.x:.2f}, {self.y:.2f})'


@dataclass(frozen=True)
class WaypointsStep:
    """
    Follow poses (x, y, yaw) in the map frame (m, rad) with Nav2's FollowWaypoints.

    The step is 'reached' when the action ends with no missed waypoint within timeout_s
    (simulated s); otherwise 'failed', its message naming each missed waypoint.
    """

    poses: Tuple[Pose, ...]
    timeout_s: float

    kind = 'waypoints'

    def describe(self) -> str:
        """Return e.g. 'waypoints (3.50, 1.50) -> (5.10, 6.20)'."""
        return 'waypoints ' + ' -> '.join(f'({x:.2f}, {y:.2f})' for x, y, _ in self.poses)


@dataclass(frozen=True)
class CommandStep:
    """Send a robot_controller text command and wait until it is done (timeout_s)."""

    text: str
    timeout_s: float
    motion: Motion  # what robot_controller's parser makes of text (default limits)
    expect: str = 'done'   # done | stopped | rejected | any

    kind = 'command'

    def describe(self) -> str:
        """Return e.g. "command 'forward 1.5 m'"."""
        return f'command {self.text!r}'


@dataclass(frozen=True)
class CmdVelStep:
    """
    Hold the body twist vx, vy (m/s), wz (rad/s) for duration_s on a command source's topic.

    source names an input of the command chain's twist_mux (mecanum_safety
    config/twist_mux.yaml: 'scenario' by default, 'teleop_keyboard', 'joystick',
    'external', ...); topic is that input's topic. Like every source, it goes through
    the collision monitor and the zone guard.
    """

    vx: float
    vy: float
    wz: float
    duration_s: float
    source: str = 'scenario'
    topic: str = 'cmd_vel_scenario'

    kind = 'cmd_vel'

    def describe(self) -> str:
        """Return e.g. 'cmd_vel (0.30, 0.00, 0.00) for 3.0 s from teleop_keyboard'."""
        source = '' if self.source == 'scenario' else f' from {self.source}'
        return (f'cmd_vel ({self.vx:.2f}, {self.vy:.2f}, {self.wz:.2f}) for '
                f'{self.duration_s:.1f} s{source}')


@dataclass(frozen=True)
class FreezeStep:
    """
    Hang the process that runs node for duration_s simulated seconds (SIGSTOP, SIGCONT).

    A hung node: e.g. amcl, so that localisation goes stale. In a composed system the
    node's whole container hangs (e.g. amcl with map_server and the navigator). The step
    ends at once: the next steps run while the node hangs; it resumes duration_s later
    (or when the run ends).
    """

    node: str
    duration_s: float

    kind = 'freeze'

    def describe(self) -> str:
        """Return e.g. 'freeze amcl for 5.0 s'."""
        return f'freeze {self.node} for {self.duration_s:.1f} s'


@dataclass(frozen=True)
class WaitStep:
    """Do nothing for duration_s simulated seconds."""

    duration_s: float

    kind = 'wait'

    def describe(self) -> str:
        """Return e.g. 'wait 2.0 s'."""
        return f'wait {self.duration_s:.1f} s'


Step = Union[GoalStep, WaypointsStep, CommandStep, CmdVelStep, WaitStep, FreezeStep]


@dataclass(frozen=True)
class Criteria:
    """What a run must satisfy besides its steps; None or False disables a criterion."""

    max_duration_s: Optional[float] = None
    no_collision: bool = True
    stay_in_zone: bool = True
    max_localization_error_m: Optional[float] = None


@dataclass(frozen=True)
class Scenario:
    """
    A validated scenario file.

    world_file is the base world file; map_name (the file's ``map``) is a map name
    (mecanum_map_server/maps) or an absolute path; spawn and initial_pose are (x m, y m,
    yaw rad); authorised_zone is the Zone (mecanum_safety.zone) or None (no
    zone); moving_obstacles
    are the extra entries in the world file's format; world is the built scenario world
    (see scenario_world_document).
    """

    name: str
    source: Path
    world_file: Path
    map_name: str
    spawn: Pose
    initial_pose: Pose
    steps: Tuple[Step, ...]
    description: str = ''
    floor_friction_coefficient: float = 0.0
    sensor_noise_scale: float = 1.0
    real_time_factor: float = 1.0
    seed: int = 0
    authorised_zone: Optional[Zone] = None
    moving_obstacles: Tuple[Dict[str, Any], ...] = ()
    criteria: Criteria = Criteria()
    expect: str = 'pass'
    world: Optional[World] = field(default=None, compare=False, repr=False)

    @property
    def goals(self) -> List[GoalStep]:
        """Return the goal steps, in order."""
        return [step for step in self.steps if isinstance(step, GoalStep)]

    @property
    def goal_poses(self) -> List[Pose]:
        """Return every pose the robot is sent to (goals and waypoints), in order."""
        poses: List[Pose] = []
        for step in self.steps:
            if isinstance(step, GoalStep):
                poses.append((step.x, step.y, step.yaw))
            elif isinstance(step, WaypointsStep):
                poses.extend(step.poses)
        return poses


@dataclass
class StepResult:
    """
    What happened to one step, as the runner saw it (times are simulated seconds).

    outcome: goal 'reached' | 'refused' (rejected, or ended with an error code before
    moving) | 'failed' (ended with an error code) | 'timeout' (timeout_s elapsed, goal
    canceled); waypoints 'reached' | 'failed' (a waypoint missed: error_code is the
    first missed one's, error_message names each) | 'refused' | 'timeout'; command
    'done' | 'stopped' (the command chain held it: robot_controller ended it short) |
    'rejected' | 'interrupted' | 'timeout'; cmd_vel, wait and freeze 'done'; any step
    'aborted' when the run stopped during it. error_code is the NavigateToPose result
    code (0 otherwise).
    """

    kind: str
    outcome: str
    error_code: int = 0
    error_message: str = ''
    start_s: float = 0.0
    end_s: float = 0.0

    @property
    def duration_s(self) -> float:
        """Return end_s - start_s."""
        return self.end_s - self.start_s


def _empty_track() -> np.ndarray:
    return np.zeros((0, 4))


@dataclass
class RunRecord:
    """
    What the runner recorded during one run (times are simulated seconds).

    truth and estimate are (N, 4) arrays of t, x, y, yaw (map frame): the simulator's
    ground truth and the localisation estimate. duration_s runs from the start of the
    first step to the end of the last; aborted says why the run stopped early (e.g.
    'interrupted', 'a node crashed: ...'), None when it ran to its end.
    """

    truth: np.ndarray = field(default_factory=_empty_track)
    estimate: np.ndarray = field(default_factory=_empty_track)
    collision_times: List[float] = field(default_factory=list)
    #: (t, node, state, x, y): each time the command chain stopped or held the robot
    #: (collision_monitor or zone_guard STOP) or robot_controller refused or stopped a
    #: command, with the robot's true position then.
    safety_events: List[Tuple[float, str, str, float, float]] = field(default_factory=list)
    step_results: List[StepResult] = field(default_factory=list)
    duration_s: float = 0.0
    aborted: Optional[str] = None


@dataclass(frozen=True)
class CriterionResult:
    """One line of a verdict: a step or a criterion, whether it passed, and why."""

    name: str
    passed: bool
    detail: str


@dataclass(frozen=True)
class Verdict:
    """The judgement of one run: 'pass' when every criterion passed."""

    scenario: str
    expected: str
    verdict: str
    criteria: Tuple[CriterionResult, ...]

    @property
    def as_expected(self) -> bool:
        """Return whether the verdict is the one the scenario expects."""
        return self.verdict == self.expected

    @property
    def first_failure(self) -> Optional[CriterionResult]:
        """Return the first criterion that failed, or None."""
        return next((c for c in self.criteria if not c.passed), None)


# --- loading -------------------------------------------------------------------------


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


class _Parser:
    """Checks one scenario document; every failure names the file and the key."""

    def __init__(self, path: Path):
        self.path = path
        self.label = path.name

    def fail(self, key: str, message: str) -> NoReturn:
        """Raise ScenarioError for `key`."""
        raise ScenarioError(f'{self.label}: {key}: {message}' if key
                            else f'{self.label}: {message}')

    def mapping(self, value: Any, key: str, required: Sequence[str] = (),
                optional: Sequence[str] = ()) -> Dict[str, Any]:
        """Check value is a mapping with the required keys and no unknown ones."""
        allowed = ', '.join(list(required) + list(optional))
        if not isinstance(value, dict):
            self.fail(key, f'must be a mapping with keys {allowed}, not {value!r}')
        for name in value:
            if name not in required and name not in optional:
                self.fail(_join(key, str(name)), f'unknown key (allowed: {allowed})')
        for name in required:
            if name not in value:
                self.fail(key or 'scenario', f"missing key '{name}'")
        return value

    def number(self, value: Any, key: str) -> float:
        """Return value as a finite float."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(key, f'must be a number, not {value!r}')
        if not math.isfinite(value):
            self.fail(key, f'must be a finite number, not {value}')
        return float(value)

    def positive(self, value: Any, key: str) -> float:
        """Return value as a finite float > 0."""
        number = self.number(value, key)
        if number <= 0.0:
            self.fail(key, f'must be > 0, not {value}')
        return number

    def optional_positive(self, value: Any, key: str) -> Optional[float]:
        """Return None for null, else a finite float > 0."""
        return None if value is None else self.positive(value, key)

    def boolean(self, value: Any, key: str) -> bool:
        """Return value if it is true or false."""
        if not isinstance(value, bool):
            self.fail(key, f'must be true or false, not {value!r}')
        return value

    def choice(self, value: Any, key: str, choices: Sequence[str]) -> str:
        """Return value if it is one of choices."""
        if not isinstance(value, str) or value not in choices:
            self.fail(key, f'must be one of {", ".join(choices)}, not {value!r}')
        return value

    def text(self, value: Any, key: str) -> str:
        """Return value if it is a non-empty string."""
        if not isinstance(value, str) or not value.strip():
            self.fail(key, f'must be a non-empty string, not {value!r}')
        return value

    def pose(self, value: Any, key: str) -> Pose:
        """Return (x, y, yaw) from {x, y, yaw} (yaw optional, 0)."""
        raw = self.mapping(value, key, ('x', 'y'), ('yaw',))
        return (self.number(raw['x'], f'{key}.x'), self.number(raw['y'], f'{key}.y'),
                self.number(raw.get('yaw', 0.0), f'{key}.yaw'))

    def parse(self, doc: Any) -> Scenario:
        """Check the whole document and return the Scenario."""
        if not isinstance(doc, dict) or 'scenario' not in doc:
            self.fail('', 'expected a top-level "scenario:" mapping')
        if len(doc) != 1:
            other = next(key for key in doc if key != 'scenario')
            self.fail(str(other), 'unknown top-level key (only "scenario:" is allowed)')
        raw = self.mapping(doc['scenario'], '', ('name', 'world', 'steps'),
                           [k for k in SCENARIO_KEYS if k not in ('name', 'world', 'steps')])
        name = self.text(raw['name'], 'name')
        if not _NAME.fullmatch(name):
            self.fail('name', f'must be letters, digits, _ and - only, not {name!r}')
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
                               'floor_friction_coefficient')
        if friction < 0.0:
            self.fail('floor_friction_coefficient', f'must be >= 0, not {friction}')
        noise_scale = self.number(raw.get('sensor_noise_scale', 1.0), 'sensor_noise_scale')
        if noise_scale < 0.0:
            self.fail('sensor_noise_scale', f'must be >= 0, not {noise_scale}')
        real_time_factor = self.positive(raw.get('real_time_factor', 1.0), 'real_time_factor')
        seed = raw.get('seed', 0)
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            self.fail('seed', f'must be an integer >= 0, not {seed!r}')
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
            real_time_factor=real_time_factor,
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
        """Return one step: exactly one of goal, command, cmd_vel, wait."""
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
                'criteria.max_localization_error_m'))


def _join(prefix: str, key: str) -> str:
    return f'{prefix}.{key}' if prefix else key


_MOVING = re.compile(r"^moving_obstacles\[(\d+)\]((?: '[^']*')?): (.*)$", re.DOTALL)


def _scenario_key(world_message: str, base_moving: int) -> Tuple[str, str]:
    """Map a world loader message (without the file label) to (scenario key, message)."""
    if world_message.startswith('robot_start: '):
        message = world_message[len('robot_start: '):]
        return 'spawn', message.replace('the test_zone', 'the authorised_zone')
    if world_message.startswith('test_zone: '):
        return 'authorised_zone', world_message[len('test_zone: '):]
    match = _MOVING.match(world_message)
    if match:
        index, name, message = int(match.group(1)), match.group(2), match.group(3)
        if index >= base_moving:
            named = f'{name.strip()}: ' if name else ''
            return f'moving_obstacles[{index - base_moving}]', named + message
        return 'spawn', f"the world's moving obstacle{name}: {message}"
    return 'world', world_message


# --- judging -------------------------------------------------------------------------


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


def judge(scenario: Scenario, record: RunRecord) -> Verdict:
    """Judge a run: one CriterionResult per step and per enabled criterion."""
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
            f'max_duration_s: {duration:.1f} s {sign} {criteria.max_duration_s:g} s'))
    if criteria.no_collision:
        times = sorted(float(t) for t in record.collision_times)
        detail = f'no_collision: {len(times)} collision{"" if len(times) == 1 else "s"}'
        if times:
            detail += f', first at t={times[0]:.1f} s'
        results.append(CriterionResult('no_collision', not times, detail))
    if criteria.stay_in_zone:
        results.append(_judge_zone(scenario.authorised_zone, record.truth))
    if criteria.max_localization_error_m is not None:
        results.append(_judge_localization(criteria.max_localization_error_m, record))
    verdict = 'pass' if all(r.passed for r in results) else 'fail'
    return Verdict(scenario.name, scenario.expect, verdict, tuple(results))


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
        return _judge_goal(name, head, step, result, took)
    expected = (step.expect if isinstance(step, CommandStep)
                else 'reached' if isinstance(step, WaypointsStep) else 'done')
    passed = expected == 'any' or outcome == expected
    detail = f'{head}: {outcome}{took}'
    if result.error_message:
        detail += f': {result.error_message}'
    return CriterionResult(name, passed,
                           detail if passed else detail + f' (expected {expected})')


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


def _judge_zone(zone: Optional[Zone], truth: Any) -> CriterionResult:
    if zone is None:
        return CriterionResult('stay_in_zone', True, 'stay_in_zone: no zone declared')
    track = track_array(truth, 'truth')
    if len(track) == 0:
        return CriterionResult('stay_in_zone', False, 'stay_in_zone: no ground truth recorded')
    inside = zone.contains(track[:, 1], track[:, 2])
    if np.all(inside):
        return CriterionResult('stay_in_zone', True,
                               f'stay_in_zone: inside at all {len(track)} true poses')
    t, x, y, _ = track[int(np.argmin(inside))]
    return CriterionResult('stay_in_zone', False,
                           f'stay_in_zone: left the zone at t={t:.1f} s ({x:.2f}, {y:.2f})')


def _judge_localization(limit_m: float, record: RunRecord) -> CriterionResult:
    errors = localization_errors(record.truth, record.estimate)
    if len(errors) == 0:
        return CriterionResult('max_localization_error_m', False,
                               'max_localization_error_m: no estimate within the ground '
                               "truth's time span")
    worst = int(np.argmax(errors[:, 1]))
    t, error = errors[worst]
    if error <= limit_m:
        return CriterionResult('max_localization_error_m', True,
                               f'max_localization_error_m: {error:.2f} m <= {limit_m:g} m '
                               f'({len(errors)} estimates)')
    return CriterionResult('max_localization_error_m', False,
                           f'max_localization_error_m: {error:.2f} m at t={t:.1f} s > '
                           f'{limit_m:g} m')
