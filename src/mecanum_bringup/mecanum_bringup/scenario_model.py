"""
The scenario data model: steps, criteria, scenarios, run records and verdicts (pure data).

A :class:`Scenario` is what :mod:`mecanum_bringup.scenario_loader` makes of a scenario
file (the format is described there): its steps (:class:`GoalStep`,
:class:`WaypointsStep`, :class:`CommandStep`, :class:`CmdVelStep`, :class:`FreezeStep`,
:class:`WaitStep`, :class:`FaultStep`) and :class:`Criteria`. A :class:`RunRecord` is
what the runner recorded during one run (a :class:`StepResult` per step);
:mod:`mecanum_bringup.scenario_judge` turns it into a :class:`Verdict` of
:class:`CriterionResult` s. Metres, seconds and radians; poses in the map frame.
"""

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple, Union

from mecanum_safety.zone import Zone
import numpy as np
from robot_controller.command_parser import Motion
from robot_simulation.faults import FaultSpec
from robot_simulation.world import World

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

GOAL_EXPECTATIONS = ('reached', 'refused', 'any')
VERDICTS = ('pass', 'fail')
STEP_KINDS = ('goal', 'waypoints', 'command', 'cmd_vel', 'wait', 'freeze', 'fault')
COMMAND_EXPECTATIONS = ('done', 'stopped', 'rejected', 'any')


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

    A hung node: e.g. amcl, so that localisation goes stale. It is the fault node_frozen
    with onset 0 (:meth:`as_fault`), injected the same way: in a composed system the
    runner runs the node in a process of its own, so only it hangs. The step ends at
    once: the next steps run while the node hangs; it resumes duration_s later (or when
    the run ends).
    """

    node: str
    duration_s: float

    kind = 'freeze'

    def describe(self) -> str:
        """Return e.g. 'freeze amcl for 5.0 s'."""
        return f'freeze {self.node} for {self.duration_s:.1f} s'

    def as_fault(self) -> FaultSpec:
        """Return the same thing as a fault: node_frozen at the step's start."""
        return FaultSpec('node_frozen', 0.0, self.duration_s, (('node', self.node),))


@dataclass(frozen=True)
class FaultStep:
    """
    Inject one fault of robot_simulation.faults' vocabulary; fault.onset_s counts from the step.

    The step ends at once (outcome 'done'): the next steps run while the fault acts, from
    the step's start + fault.onset_s for fault.duration_s (None: to the end of the run).
    The simulator injects the 'simulator' kinds (sensors, wheels, body, serial line), the
    runner the 'runner' ones (node_frozen, node_killed, estop).
    """

    fault: FaultSpec

    kind = 'fault'

    def describe(self) -> str:
        """Return e.g. 'fault lidar_blinded at +2 s for 5 s'."""
        return f'fault {self.fault.describe().replace(" at ", " at +", 1)}'


@dataclass(frozen=True)
class WaitStep:
    """Do nothing for duration_s simulated seconds."""

    duration_s: float

    kind = 'wait'

    def describe(self) -> str:
        """Return e.g. 'wait 2.0 s'."""
        return f'wait {self.duration_s:.1f} s'


Step = Union[GoalStep, WaypointsStep, CommandStep, CmdVelStep, WaitStep, FreezeStep, FaultStep]


@dataclass(frozen=True)
class Criteria:
    """What a run must satisfy besides its steps; None or False disables a criterion."""

    max_duration_s: Optional[float] = None
    no_collision: bool = True
    stay_in_zone: bool = True
    max_localization_error_m: Optional[float] = None
    #: Judge each injected fault's reaction (mecanum_bringup.fault_reactions).
    fault_reactions: bool = False


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
    #: The simulated board: 'core' (board_core in the simulator) or 'firmware' (main.py
    #: as flashed, MicroPython's unix port, in lockstep).
    board: str = 'core'
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
    'rejected' | 'interrupted' | 'timeout'; cmd_vel, wait, freeze and fault 'done'; any step
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

    faults lists every fault the run injected (fault and freeze steps), in the order of
    their steps: the fault's mapping (FaultSpec.as_dict: kind, onset_s, duration_s and
    its parameters) with onset_s absolute (simulated s), plus 'where' ('simulator' or
    'runner'), 'step' (its step's number, from 1), 'began_s' and 'ended_s' (simulated s:
    when the runner applied and ended it, or the simulator reported it started and
    ended; None: not within the run), and for a kidnap 'applied' (false: the simulator
    refused it) and 'outcome' (the simulator's account).
    """

    truth: np.ndarray = field(default_factory=_empty_track)
    estimate: np.ndarray = field(default_factory=_empty_track)
    collision_times: List[float] = field(default_factory=list)
    #: (t, node, state, x, y): each time the command chain stopped or held the robot
    #: (collision_monitor or zone_guard STOP) or robot_controller refused or stopped a
    #: command, with the robot's true position then.
    safety_events: List[Tuple[float, str, str, float, float]] = field(default_factory=list)
    #: (t, node, state) at each change of a chain stage's state (twist_mux,
    #: collision_monitor, zone_guard; numbers in a state do not make a change).
    chain_states: List[Tuple[float, str, str]] = field(default_factory=list)
    step_results: List[StepResult] = field(default_factory=list)
    duration_s: float = 0.0
    aborted: Optional[str] = None
    faults: List[Dict[str, Any]] = field(default_factory=list)
    #: (M, 4) t, k, x, y: the moving obstacles' true centres (k: the index in the
    #: scenario world's moving_obstacles), stamped as the ground truth they came with.
    movers: np.ndarray = field(default_factory=_empty_track)


@dataclass(frozen=True)
class CriterionResult:
    """
    One line of a verdict: a step or a criterion, whether it passed, and why.

    margin: how far the run was from failing it, in margin_unit ('m' or 's'): positive
    when it passed, <= 0 when it failed; None where the criterion has no measure (a
    step's outcome other than in time or too late, 'completed', 'fault_reaction').
    """

    name: str
    passed: bool
    detail: str
    margin: Optional[float] = None
    margin_unit: str = ''


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
