"""
run_scenarios: run scenario files with the whole simulated robot and judge them.

Usage (pip setup; on an apt install ``ros2 run mecanum_bringup run_scenarios``)::

    ros2 run mecanum_bringup run_scenarios PATH [PATH ...] [--out DIR]
        [--junit FILE] [--real-time-factor X|max] [--no-lockstep] [--record] [--foxglove]
        [--no-compose] [--jobs N] [--board core|firmware] [--cold] [--quiet]

PATH is a scenario file or a folder of them (see :mod:`mecanum_bringup.scenario_loader` for the
format; ``src/mecanum_bringup/scenarios`` holds the project's). Each scenario runs
isolated: in a ROS domain no other process of this machine holds, with localhost-only
discovery, in its own processes (mecanum_bringup robot.launch through the launch
runner: simulator, control stack on the simulated ESP32, description, EKF, map_server +
amcl, navigator, velocity smoother, collision monitor, robot_controller), headless, on
simulated time, and every one of those processes is gone when the scenarios end,
whatever happened (between two scenarios they may stay, without nodes: warm stacks).
The nodes run composed (launch runner ``--compose``: the control chain in one process,
localisation and navigation in another, as Nav2's use_composition), which costs far
less CPU on simulated time; ``--no-compose`` runs each node in its own process. A node
that a freeze or a node fault acts on runs in a process of its own when composed (the
run's ``composition.yaml``), so that the fault hits that node alone.

Warm stacks: one scenario after another in a process (the only one, or each --jobs
worker) runs on the same processes. After a run that ended cleanly its processes close
their nodes and wait, idle; the next run makes its own nodes in them from its own launch
file (mecanum_bringup.launch_runner ``--reloadable``, mecanum_control.node_reload):
new nodes, so no state of the last run survives, without a new interpreter, imports and
DDS participant each time. A run that failed, was interrupted or acted on the processes
(node faults) stops them; the next starts cold, as does a run that needs other
processes (recording, Foxglove). ``--cold`` starts every run's processes anew.

The runner drives the steps (Nav2's NavigateToPose and FollowWaypoints goals, text commands
on ``control_command``, twists on a command source's topic of the command chain, waits,
faults: see :class:`FaultInjector`) and records the simulator's ground truth
(``ground_truth/odom``), amcl's estimate (``amcl_pose``), the collisions
(``simulation/collisions``) and the plans (``plan``). Each scenario gets a folder
``DIR/NAME/``: ``summary.json`` (with ``faults``: each fault injected, and when; see
RunRecord.faults), ``run.png`` (map, plans, driven path, ground truth, collisions),
``truth.csv`` and ``estimate.csv`` (t_s, x_m, y_m, yaw_rad in the map frame),
``system.log`` (every node's output) and, with
``--record``, ``bag/`` (an MCAP rosbag2 of every topic). The table of verdicts is
printed at the end; ``--junit`` writes it as JUnit XML for CI.

Simulated time runs in lockstep with the stack (robot_simulation.lockstep): the
simulator steps on only when the stack has answered each /clock, so a loaded machine
makes a run slower, not different. ``--real-time-factor`` is then an upper bound and
``max`` runs as fast as the stack answers; ``--no-lockstep`` runs on the wall clock (as
the demo does: that checks that the stack keeps up in real time).

``--board firmware`` runs every scenario on the firmware as flashed (firmware/main.py
under MicroPython's unix port, stepped with the physics) instead of the firmware's
core inside the simulator (a scenario's own ``board`` says the same for it).

``--jobs N`` runs up to N scenarios at once, each in a worker process of its own with its
own ROS domain, processes and report folder, exactly as one at a time (in lockstep the
verdicts do not depend on the other runs' load); the table keeps the files' order.

Exit code: 0 when every scenario got the verdict it expects (a scenario with
``expect: fail`` must fail), 1 otherwise, 2 when a file is invalid or nothing was found.
Ctrl-C (or SIGTERM) stops the running scenario cleanly (its report and recording are still written)
and skips the others.
"""

import argparse
import atexit
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, replace
import json
import math
import multiprocessing
import os
from pathlib import Path
import re
import signal
import subprocess
import sys
import threading
import time
from typing import Any, Callable, Dict, Iterable, List, Optional, Sequence, Set, Tuple
import uuid

from mecanum_bringup.isolation import (
    isolated_environment, lease_domain_id, processes_with_variable)
from mecanum_bringup.launch_runner import die_with_parent
from mecanum_bringup.scenario_judge import error_label, judge
from mecanum_bringup.scenario_loader import (
    find_scenarios, load_scenario, scenario_world_document, ScenarioError)
from mecanum_bringup.scenario_model import (
    CmdVelStep, CommandStep, FaultStep, FreezeStep, GoalStep, RunRecord, Scenario, StepResult,
    WaitStep, WaypointsStep)
from mecanum_bringup.scenario_report import (
    junit_xml, plot_run, results_table, ScenarioResult, summary_json)
from mecanum_safety import zone_guard
from mecanum_safety.zone import zone_file_text
import numpy as np
from robot_simulation.faults import FaultSpec, SIMULATOR
from robot_simulation.simulator import BOARDS
import yaml

#: Environment variable carrying a scenario run's marker (to find leftover processes).
RUN_MARKER = 'MECANUM_SCENARIO_RUN'
#: Output lines that say the system is ready for the first step, and how long to wait.
READY_PATTERNS = (('[ekf_filter_node]', 'EKF started'),
                  # Both of its sensors fused (the IMU waits for its mount on /tf_static).
                  ('[ekf_filter_node]', 'odom0 odom: first message taken in'),
                  ('[ekf_filter_node]', 'imu0 imu/data_raw: first message taken in'),
                  ('[navigator]', 'ready for goals'),
                  ('[hardware_interface]', 'IMU calibrated at rest'))
READY_TIMEOUT_S = 120.0
#: Wall seconds before a goal's result is asked for again (a request lost in discovery).
RESULT_REQUEST_S = 1.0
#: Publishing period (simulated s) of a cmd_vel step's twist.
CMD_VEL_PERIOD_S = 0.05
#: How far (m) the robot may move during a goal that ended in an error and still count
#: as 'refused' (rejected before moving) rather than 'failed'.
REFUSED_MOTION_M = 0.05

Progress = Callable[[str], None]
#: Set by SIGINT (Ctrl-C) or SIGTERM (:func:`interrupt`): the running scenario stops
#: cleanly, the others are skipped.
INTERRUPTED = threading.Event()
#: The first signal that interrupted the run (its number).
_INTERRUPTION = {'signum': signal.SIGINT}
SIGNAL_NAMES = {signal.SIGINT: 'Ctrl-C', signal.SIGTERM: 'SIGTERM'}


def interrupt(signum: int = signal.SIGINT, _frame=None) -> None:
    """Stop the run cleanly (a handler of SIGINT and SIGTERM): set INTERRUPTED."""
    if not INTERRUPTED.is_set():
        _INTERRUPTION['signum'] = signum
    INTERRUPTED.set()


def interrupted_by() -> str:
    """Return what interrupted the run: 'Ctrl-C' or 'SIGTERM'."""
    signum = _INTERRUPTION['signum']
    return SIGNAL_NAMES.get(signum, f'signal {signum}')


@contextmanager
def stopping_cleanly_on_signals(handler: Callable[[int, object], None] = interrupt):
    """
    Within: SIGINT and SIGTERM call handler (default :func:`interrupt`); then as before.

    Both are unblocked too: a blocked signal stays blocked across exec, and a process
    started with SIGINT blocked (as ros2 launch's children may be) never saw launch's
    SIGINT, which escalated to SIGTERM after 5 s.
    """
    previous = {number: signal.signal(number, handler)
                for number in (signal.SIGINT, signal.SIGTERM)}
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})
    try:
        yield
    finally:
        for number, handler_before in previous.items():
            signal.signal(number, handler_before)


@dataclass
class RunOptions:
    """How to run: output folder, speed override, recording, live view, progress."""

    out_dir: Path
    #: Overrides the scenarios' real_time_factor; 0 = 'max' (with lockstep: as fast as
    #: the stack answers).
    real_time_factor: Optional[float] = None
    record: bool = False
    foxglove: bool = False
    progress: Optional[Progress] = None
    status_period_s: float = 10.0
    #: Group the nodes into containers (launch runner --compose).
    compose: bool = True
    #: Simulated time waits for the stack (robot_simulation.lockstep).
    lockstep: bool = True
    #: Overrides the scenarios' board ('core' or 'firmware'); None: each its own.
    board: Optional[str] = None
    #: Called with the SystemProcess once it is up, and with None when the steps end
    #: (for benchmarks that watch the node processes).
    on_system: Optional[Callable[[Optional['SystemProcess']], None]] = None
    #: Warm stack: after a run that ended cleanly, keep the system's processes (their
    #: nodes unloaded, idle) for this process's next run, which loads its nodes into
    #: them instead of starting them anew (see :class:`KeptSystem`). False: every run
    #: starts its processes and stops them. run_scenarios and run_sweep: on (--cold: off).
    warm: bool = False


# --- the files of a run --------------------------------------------------------------

def real_time_factor(scenario: Scenario, options: RunOptions) -> float:
    """Return the run's real-time factor: the override, else the scenario's (0 = max)."""
    if options.real_time_factor is not None:
        return options.real_time_factor
    return scenario.real_time_factor


def parse_real_time_factor(text: str) -> float:
    """Parse --real-time-factor: a number > 0, or 'max' (returned as 0)."""
    if text.strip().lower() == 'max':
        return 0.0
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(f"must be a number > 0 or 'max', got {text!r}")
    return value


def write_run_files(scenario: Scenario, run_dir: Path, options: RunOptions) -> Path:
    """
    Write the scenario's world, zone file, navigator parameters and launch file into run_dir.

    The launch file includes mecanum_bringup robot.launch.yaml with the scenario's world
    (spawn, zone and moving obstacles built in), map, initial pose (known: 5 cm / 3 deg
    spread), friction, sensor noise scale, seed and real-time factor, the navigator's
    parameters and the authorised zone as a zone file (zone.yaml: the one declaration
    that the planner, the zone guard and robot_controller load, and that the judge uses);
    plus the bag recorder with options.record, the Foxglove bridge with options.foxglove.
    Returns the launch file's path.
    """
    run_dir.mkdir(parents=True, exist_ok=True)
    world_file = run_dir / 'world.yaml'
    world_file.write_text(yaml.safe_dump(scenario_world_document(scenario), sort_keys=False),
                          encoding='utf-8')
    from ament_index_python.packages import get_package_share_directory
    nav_share = Path(get_package_share_directory('mecanum_navigation'))
    params = yaml.safe_load((nav_share / 'config' / 'nav2_params.yaml').read_text())
    nav_params = run_dir / 'nav2_params.yaml'
    nav_params.write_text(yaml.safe_dump(params, sort_keys=False), encoding='utf-8')
    zone_file = run_dir / 'zone.yaml'
    zone_file.write_text(zone_file_text(scenario.authorised_zone), encoding='utf-8')
    x, y, yaw = scenario.initial_pose
    rtf = real_time_factor(scenario, options)
    args = {'world': str(world_file), 'map': scenario.map_name,
            'initial_pose_x': x, 'initial_pose_y': y, 'initial_pose_yaw': yaw,
            'initial_pose_std_xy': 0.05, 'initial_pose_std_yaw': 0.05,
            'real_time_factor': rtf, 'lockstep': str(options.lockstep).lower(),
            'seed': scenario.seed,
            'floor_friction_coefficient': scenario.floor_friction_coefficient,
            'sensor_noise_scale': scenario.sensor_noise_scale,
            'board': options.board or scenario.board,
            'nav_params_file': str(nav_params), 'zone_file': str(zone_file),
            'board_port': str(run_dir / 'ttySIM'),
            'estop_latch_file': str(run_dir / 'estop_latched')}
    entries: List[Dict] = [{'include': {
        'file': '$(find-pkg-share mecanum_bringup)/launch/robot.launch.yaml',
        'arg': [{'name': name, 'value': str(value)} for name, value in args.items()]}}]
    sim_time = [{'name': 'use_sim_time', 'value': True}]   # a bool: quoted, it stays text
    if options.record:
        entries.append({'node': {'pkg': 'mecanum_bringup', 'exec': 'bag_recorder',
                                 'name': 'bag_recorder', 'param': sim_time + [
                                     {'name': 'output', 'value': str(run_dir / 'bag')}]}})
    if options.foxglove:
        entries.append({'node': {'pkg': 'mecanum_bringup', 'exec': 'foxglove_bridge',
                                 'name': 'foxglove_bridge', 'param': sim_time}})
    launch_file = run_dir / 'scenario.launch.yaml'
    launch_file.write_text(yaml.safe_dump({'launch': entries}, sort_keys=False),
                           encoding='utf-8')
    return launch_file


# --- the processes -------------------------------------------------------------------

class SystemProcess:
    """The launch runner running one scenario's system; output to a log file and memory."""

    def __init__(self, launch_file: Path, env: Dict[str, str], log_file: Path,
                 compose: bool = True, composition_file: Optional[Path] = None,
                 reloadable: bool = False):
        """
        Start the launch runner in its own session, with a marker in its environment.

        compose groups the nodes into containers: those of composition_file (default:
        mecanum_bringup's config/composition.yaml). reloadable: the runner takes unload
        and load commands (:meth:`unload`, :meth:`load`); its standard input closing
        stops it.
        """
        self.marker = uuid.uuid4().hex
        self.lines: List[str] = []
        self._since = 0     # the first line of this run (has_line, tail)
        self._lock = threading.Lock()
        self._log = open(log_file, 'w', encoding='utf-8')
        self.compose = compose
        self.composition_file = composition_file
        self.reloadable = reloadable
        composition = ['--composition', str(composition_file)] if composition_file else []
        self.process = subprocess.Popen(
            [sys.executable, '-m', 'mecanum_bringup.launch_runner',
             *(['--reloadable'] if reloadable else []),
             *(['--compose', *composition] if compose else []), str(launch_file)],
            env=dict(env, **{RUN_MARKER: self.marker}), stdout=subprocess.PIPE,
            stdin=subprocess.PIPE if reloadable else subprocess.DEVNULL,
            stderr=subprocess.STDOUT, text=True, start_new_session=True,
            # A runner killed outright (SIGKILL, a Ray worker or node lost) takes its
            # system with it: the launch runner stops every node when it gets SIGTERM.
            preexec_fn=die_with_parent)
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.process.stdout:
            line = line.rstrip('\n')
            with self._lock:
                self.lines.append(line)
                self._log.write(line + '\n')

    def node_pids(self) -> Dict[str, int]:
        """Return {node label: pid} from the launch runner's (re)started lines so far."""
        pids = {}
        with self._lock:
            for line in self.lines:   # 'started X (pid N)', 'restarted X (start 2, pid N)'
                match = _STARTED.match(line)
                if match:
                    pids[match.group(1)] = int(match.group(2))
        return pids

    def pid_of(self, node: str) -> Optional[int]:
        """Return the pid of the process running node (its container when composed)."""
        pids = self.node_pids()
        if node in pids:
            return pids[node]
        if not self.compose:
            return None
        from mecanum_bringup.composition import load_composition
        from mecanum_bringup.launch_runner import default_composition_file
        file = self.composition_file or default_composition_file()
        for container, members in load_composition(file).items():
            if node in members and container in pids:
                return pids[container]
        return None

    def has_line(self, *parts: str) -> bool:
        """Tell whether an output line of this run so far contains every one of parts."""
        with self._lock:
            return any(all(part in line for part in parts)
                       for line in self.lines[self._since:])

    def _command(self, text: str, done: str, failed: Tuple[str, ...],
                 timeout_s: float) -> bool:
        """Send the runner a reload command; wait for its done line (False: it failed)."""
        with self._lock:
            start = len(self.lines)
        try:
            self.process.stdin.write(text)
            self.process.stdin.flush()
        except (OSError, ValueError, AttributeError):
            return False
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and self.alive():
            with self._lock:
                for line in self.lines[start:]:
                    if line.startswith(done):
                        return True
                    if line.startswith(failed):
                        return False
            time.sleep(0.02)
        return False

    def unload(self, timeout_s: float = 30.0) -> bool:
        """Have every process close its nodes and wait, idle; False: it failed (stop it)."""
        done = self.reloadable and self._command(
            'unload\n', '[runner] unloaded', ('[runner] reload failed',), timeout_s)
        with self._lock:
            self._log.flush()    # the run's log is complete (the file stays open)
        return done

    def load(self, launch_file: Path, log_file: Path, composition_file: Optional[Path],
             timeout_s: float = 90.0) -> bool:
        """
        Make the nodes of launch_file in the unloaded processes, a new run (log_file).

        False: the runner refused (other processes) or a process failed; stop it then.
        """
        if not self.reloadable or self.composition_file != composition_file:
            return False
        with self._lock:
            self._log.close()
            self._log = open(log_file, 'w', encoding='utf-8')
            self._since = len(self.lines)
        document = {'launch_file': str(launch_file), 'compose': self.compose,
                    'composition': str(composition_file) if composition_file else None}
        return self._command('load ' + json.dumps(document) + '\n', '[runner] loaded',
                             ('[runner] reload refused', '[runner] reload failed'),
                             timeout_s)

    def alive(self) -> bool:
        """Tell whether the launch runner still runs."""
        return self.process.poll() is None

    def tail(self, count: int = 20) -> str:
        """Return the last count output lines of this run."""
        with self._lock:
            return '\n'.join(self.lines[self._since:][-count:])

    def stop(self, timeout_s: float = 20.0) -> None:
        """Ctrl-C the runner (it stops every node), then kill whatever is left."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout=5.0)
        for pid in processes_with_marker(self.marker):
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        self._reader.join(timeout=5.0)
        with self._lock:
            self._log.close()


_STARTED = re.compile(r'^\[runner\] (?:re)?started (\S+) \((?:start \d+, )?pid (\d+)\)')


def processes_with_marker(marker: Optional[str] = None) -> List[int]:
    """Return the PIDs of processes of the scenario run marked marker (None: of any run)."""
    return processes_with_variable(RUN_MARKER, marker)


# --- faults --------------------------------------------------------------------------

#: The node fault kinds: they act on the process that runs the fault's 'node'.
NODE_FAULTS = ('node_frozen', 'node_killed')


def step_fault(step) -> Optional[FaultSpec]:
    """Return the fault a step injects (fault and freeze steps; onset from it), or None."""
    if isinstance(step, FaultStep):
        return step.fault
    if isinstance(step, FreezeStep):
        return step.as_fault()
    return None


def fault_nodes(scenario: Scenario) -> List[str]:
    """Return the nodes a node fault (node_frozen, node_killed, freeze) acts on, in order."""
    nodes: List[str] = []
    for step in scenario.steps:
        fault = step_fault(step)
        if fault is not None and fault.kind in NODE_FAULTS and fault.param('node') not in nodes:
            nodes.append(fault.param('node'))
    return nodes


def composition_without(containers: Dict[str, List[str]],
                        nodes: Iterable[str]) -> Dict[str, List[str]]:
    """Return the containers without nodes (each then runs alone); empty ones left out."""
    leave_out: Set[str] = set(nodes)
    kept = {name: [label for label in labels if label not in leave_out]
            for name, labels in containers.items()}
    return {name: labels for name, labels in kept.items() if labels}


def write_composition(scenario: Scenario, run_dir: Path) -> Tuple[bool, Optional[Path]]:
    """
    Return (compose, composition file) for a composed run of scenario.

    A node that a node fault acts on runs in a process of its own, so that freezing or
    killing it hits it alone, not its container's other nodes: the default composition
    without those nodes is written to run_dir/composition.yaml. (False, None) when no
    container is left; (True, None) without node faults (the default composition).
    """
    nodes = fault_nodes(scenario)
    if not nodes:
        return True, None
    from mecanum_bringup.composition import load_composition
    from mecanum_bringup.launch_runner import default_composition_file
    containers = composition_without(load_composition(default_composition_file()), nodes)
    if not containers:
        return False, None
    path = run_dir / 'composition.yaml'
    path.write_text(yaml.safe_dump({'containers': containers}, sort_keys=False),
                    encoding='utf-8')
    return True, path


class FaultInjector:
    """
    Injects a run's faults at their simulated times and records them in record.faults.

    :meth:`add` takes a fault step's fault (onset_s from the step's start, start_s). A
    'simulator' kind is sent to the simulator at once with its onset made absolute
    (driver.send_fault); the simulator applies it on its own clock and reports it
    (driver.fault_reports, read by :meth:`finish`). The runner applies
    the 'runner' kinds itself when :meth:`due` sees their time come (it is called on
    every poll of the steps, and at once by add: an onset of 0 acts at the step's start):

    - node_frozen: SIGSTOP to the process running node (system.pid_of), SIGCONT
      duration_s later (or when the run ends: :meth:`finish`);
    - node_killed: SIGKILL to it (the launch runner respawns the node, if it respawns);
      for both, the simulator's lockstep is told at once (driver.process_down): simulated
      time runs on while the process is down, as wall time does on a robot;
    - amcl_diverged: amcl's reinitialize_global_localization is called (its particles
      spread over the map); 'applied' false when no amcl serves it;
    - estop: the operator presses the e-stop (driver.set_estop(True): emergency_stop
      true) and releases it duration_s later (driver.set_estop(False): false, and the
      reset of motor_controller's latched stop), not at all when duration_s is None.

    A node that runs in no process is a RuntimeError (a misspelt node: the run aborts).
    Signals are sent with kill (os.kill), which tests replace.
    """

    def __init__(self, system, driver, record: RunRecord,
                 kill: Callable[[int, int], None] = os.kill):
        """Inject through system (pid_of) and driver (send_fault, set_estop, fault_reports)."""
        self.system = system
        self.driver = driver
        self.record = record
        self.kill = kill
        #: (simulated time s, order, fault index in record.faults, 'begin' | 'end')
        self._pending: List[Tuple[float, int, int, str]] = []
        self._order = 0
        self._specs: List[FaultSpec] = []   # absolute onsets, as record.faults
        self._stopped: Dict[int, int] = {}  # fault index -> the pid it stopped

    def add(self, fault: FaultSpec, start_s: float, step_number: int) -> Dict[str, Any]:
        """Schedule fault (onset from start_s) of step step_number; return its record."""
        absolute = replace(fault, onset_s=start_s + fault.onset_s)
        entry = dict(absolute.as_dict(), where=fault.where, step=step_number, began_s=None,
                     ended_s=None)
        index = len(self.record.faults)
        self.record.faults.append(entry)
        self._specs.append(absolute)
        if fault.where == SIMULATOR:
            self.driver.send_fault(absolute.as_dict())
        elif fault.kind in NODE_FAULTS + ('estop', 'amcl_diverged'):
            if fault.kind in NODE_FAULTS:
                self._pid(fault)   # a node no process runs: an error now, not at onset
            self._schedule(absolute.onset_s, index, 'begin')
        else:
            raise RuntimeError(f'the runner cannot inject {fault.kind} (where {fault.where})')
        self.due(start_s)
        return entry

    def due(self, now_s: float) -> None:
        """Apply the runner's actions whose simulated time has come, in time order."""
        self.driver.keep_releasing()
        while self._pending and self._pending[0][0] <= now_s:
            _, _, index, action = self._pending.pop(0)
            if action == 'begin':
                self._begin(index, now_s)
            else:
                self._end(index, now_s)

    def finish(self) -> None:
        """
        At the run's end: resume the frozen processes; date the simulator's faults.

        A runner fault still pending keeps None times (it did not act, or did not end,
        within the run). A simulator fault is dated by the simulator's reports
        (driver.fault_reports: {time_s, started, ended, instants}, each fault as
        parse_fault's mapping): began_s, ended_s, and for an instant (kidnap) also
        'applied' (false: refused) and 'outcome' (what the simulator says happened).
        """
        for index, pid in list(self._stopped.items()):
            self._signal(pid, signal.SIGCONT)
            del self._stopped[index]
        self._pending.clear()
        reports = self.driver.fault_reports()
        for spec, entry in zip(self._specs, self.record.faults):
            if spec.where == SIMULATOR:
                _date_simulator_fault(entry, spec.as_dict(), reports)

    def _schedule(self, time_s: float, index: int, action: str) -> None:
        self._order += 1
        self._pending.append((time_s, self._order, index, action))
        self._pending.sort()

    def _pid(self, fault: FaultSpec) -> int:
        node = fault.param('node')
        pid = self.system.pid_of(node)
        if pid is None:
            raise RuntimeError(f'{fault.kind}: no running process runs node {node!r}')
        return pid

    def _signal(self, pid: int, number: int) -> bool:
        try:
            self.kill(pid, number)
        except ProcessLookupError:
            return False
        return True

    def _begin(self, index: int, now_s: float) -> None:
        spec, entry = self._specs[index], self.record.faults[index]
        entry['began_s'] = now_s
        if spec.kind == 'node_frozen':
            pid = self._pid(spec)
            if self._signal(pid, signal.SIGSTOP):
                self._stopped[index] = pid
                self.driver.process_down(spec.param('node'))
        elif spec.kind == 'node_killed':
            if self._signal(self._pid(spec), signal.SIGKILL):
                self.driver.process_down(spec.param('node'))
            entry['ended_s'] = now_s
            return
        elif spec.kind == 'amcl_diverged':
            applied = self.driver.reinitialize_global_localization()
            entry['applied'] = applied
            entry['outcome'] = ('particles spread over the map' if applied else
                                'no amcl serves reinitialize_global_localization')
            entry['ended_s'] = now_s
            return
        else:
            self.driver.set_estop(True)
        if spec.duration_s is not None:
            self._schedule(spec.onset_s + spec.duration_s, index, 'end')

    def _end(self, index: int, now_s: float) -> None:
        spec, entry = self._specs[index], self.record.faults[index]
        entry['ended_s'] = now_s
        if spec.kind == 'node_frozen':
            pid = self._stopped.pop(index, None)
            if pid is not None:
                self._signal(pid, signal.SIGCONT)
        else:
            self.driver.set_estop(False)


def _date_simulator_fault(entry: Dict[str, Any], fault: Dict[str, Any],
                          reports: Sequence[Dict[str, Any]]) -> None:
    """Set entry's began_s, ended_s (and applied, outcome) from the simulator's reports."""
    for report in reports:
        time_s = report.get('time_s')
        if entry['began_s'] is None and fault in (report.get('started') or []):
            entry['began_s'] = time_s
        if entry['ended_s'] is None and fault in (report.get('ended') or []):
            entry['ended_s'] = time_s
        for instant in report.get('instants') or []:
            if entry['began_s'] is None and {key: value for key, value in instant.items()
                                             if key not in ('applied', 'outcome')} == fault:
                entry['began_s'] = entry['ended_s'] = time_s
                entry['applied'] = instant.get('applied')
                entry['outcome'] = instant.get('outcome')


# --- one scenario ----------------------------------------------------------------------

class Interrupted(Exception):
    """Ctrl-C or SIGTERM during a scenario."""


class SystemDown(Exception):
    """The system's launch runner exited during a scenario."""


def run_scenario(scenario: Scenario, options: RunOptions) -> ScenarioResult:
    """Run one scenario isolated, write its report folder and return its result."""
    say = options.progress or (lambda text: None)
    run_dir = options.out_dir / scenario.name
    started = time.monotonic()
    record = RunRecord()
    plans: List[np.ndarray] = []
    launch_file = write_run_files(scenario, run_dir, options)
    compose, composition = (write_composition(scenario, run_dir) if options.compose
                            else (False, None))
    system, lease, warm = _system_for(launch_file, run_dir, compose, composition, options)
    driver = None
    try:
        from mecanum_bringup.scenario_driver import ScenarioDriver
        driver = ScenarioDriver(lease.domain_id)
        _wait_until_ready(scenario, system, driver, say)
        say(f'{scenario.name}: system up in {time.monotonic() - started:.0f} s '
            f'({"warm: its processes reused" if warm else "cold"}, ROS_DOMAIN_ID '
            f'{lease.domain_id}); {len(scenario.steps)} steps')
        if options.on_system:
            options.on_system(system)
        try:
            _run_steps(scenario, driver, system, record, options, say)
        finally:
            if options.on_system:
                options.on_system(None)
    except Interrupted:
        record.aborted = f'interrupted ({interrupted_by()})'
    except SystemDown:
        record.aborted = 'the system stopped: ' + system.tail(5).replace('\n', ' | ')
    except Exception as error:  # noqa: B902 - a runner failure is reported, not raised
        record.aborted = f'runner error: {type(error).__name__}: {error}'
    finally:
        if driver is not None:
            _end_aborted_step(record, driver.sim_now())
            record.truth, record.estimate = driver.truth_track(), driver.estimate_track()
            record.movers = driver.movers_track()
            record.collision_times = list(driver.collision_times)
            record.safety_events = driver.safety_events()
            record.chain_states = driver.chain_states()
            plans = driver.plans()
            collision_points = driver.collision_points()
            driver.close()
        else:
            collision_points = []
        _keep_or_stop(system, lease, options.warm and record.aborted is None
                      and not INTERRUPTED.is_set() and not fault_nodes(scenario))
    if record.step_results:
        record.duration_s = record.step_results[-1].end_s - record.step_results[0].start_s
    verdict = judge(scenario, record)
    wall = time.monotonic() - started
    result = ScenarioResult.from_run(verdict, record, wall)
    summary = summary_json(scenario, record, verdict, {
        'wall_time_s': round(wall, 1),
        'real_time_factor': real_time_factor(scenario, options) or 'max',
        'lockstep': options.lockstep,
        'board': options.board or scenario.board})
    summary.setdefault('faults', record.faults)
    (run_dir / 'summary.json').write_text(json.dumps(summary, indent=1) + '\n',
                                          encoding='utf-8')
    for name, track in (('truth', record.truth), ('estimate', record.estimate)):
        np.savetxt(run_dir / f'{name}.csv', track, fmt='%.4f', delimiter=',',
                   header='t_s,x_m,y_m,yaw_rad', comments='')
    _plot(scenario, record, plans, collision_points, run_dir / 'run.png', verdict.verdict)
    return result


class KeptSystem:
    """
    A warm stack: the processes of this process's last clean run, unloaded, idle.

    Between two runs no node exists (each process closed and destroyed its nodes: their
    state goes with them) and nothing runs: the next run loads its own nodes, from its
    own launch file, into the same processes (:meth:`SystemProcess.load`), in the same
    ROS domain, still leased. A run that failed to start, was interrupted, ended with an
    error or acted on the processes (node faults) is not kept: its processes stop, and
    the next run starts cold. So is a system with other processes (the launch runner
    refuses the load). At exit (the last run done, a --jobs worker ending) the kept
    system stops; a kept system whose runner process dies stops with it (its standard
    input closes).
    """

    def __init__(self, system: SystemProcess, lease) -> None:
        """Keep system (unloaded) and its domain lease."""
        self.system = system
        self.lease = lease

    def close(self) -> None:
        """Stop the processes and give the domain back."""
        try:
            self.system.stop()
        finally:
            self.lease.release()


_KEPT: Dict[str, KeptSystem] = {}


def release_kept_system() -> None:
    """Stop the kept system, if any (at exit; tests)."""
    kept = _KEPT.pop('system', None)
    if kept is not None:
        kept.close()


atexit.register(release_kept_system)


def _system_for(launch_file: Path, run_dir: Path, compose: bool,
                composition: Optional[Path], options: RunOptions):
    """Return (system, domain lease, warm) for a run: the kept one loaded, or a new one."""
    kept = _KEPT.pop('system', None)
    if kept is not None:
        if (options.warm and kept.system.compose == compose and kept.system.alive()
                and kept.system.load(launch_file, run_dir / 'system.log', composition)):
            return kept.system, kept.lease, True
        kept.close()
    lease = lease_domain_id()
    try:
        env = isolated_environment(os.environ, lease.domain_id)
        env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
        system = SystemProcess(launch_file, env, run_dir / 'system.log', compose, composition,
                               reloadable=options.warm)
    except BaseException:
        lease.release()
        raise
    return system, lease, False


def _keep_or_stop(system: SystemProcess, lease, keep: bool) -> None:
    """After a run: keep the system for the next run (unloaded), or stop it."""
    kept = KeptSystem(system, lease)
    if keep and system.alive() and system.unload():
        _KEPT['system'] = kept
    else:
        kept.close()


def _wait_until_ready(scenario: Scenario, system: SystemProcess, driver,
                      say: Progress) -> None:
    deadline = time.monotonic() + READY_TIMEOUT_S

    def not_ready() -> str:
        missing = [' '.join(parts) for parts in READY_PATTERNS if not system.has_line(*parts)]
        return f'the system was not ready within {READY_TIMEOUT_S:.0f} s (no {missing})'

    _wait_for(lambda: all(system.has_line(*parts) for parts in READY_PATTERNS), system,
              deadline, not_ready, 0.1)
    if not driver.wait_for_navigator(timeout_s=30.0):
        raise RuntimeError('the navigate_to_pose action server did not appear')
    _wait_for(lambda: driver.sim_now() is not None and driver.latest_truth() is not None,
              system, deadline, lambda: 'no /clock or ground truth from the simulator', 0.05)
    # Localised: text commands are checked against the zone on map -> base_link, which
    # amcl completes with its first estimate (CI once saw 'forward 1 m' refused at 0.2 s
    # of simulated time, lockstep at max: no recent map -> base_link pose).
    _wait_for(lambda: len(driver.estimate_track()) > 0, system, deadline,
              lambda: 'no localisation estimate on amcl_pose (is amcl running, with its '
                      'initial pose?)', 0.05)
    # The zone guard has a pose: it needs map -> base_link (amcl's map -> odom and the
    # EKF's odom -> base_link) in its own process, whose /tf reader may match amcl's
    # writer later than the runner heard amcl_pose (a loaded machine: the first text
    # command was stopped, 'no transform map -> base_link', 1 s of simulated time after
    # the runner had seen amcl's estimate). It says so on /diagnostics once a second.
    if scenario.authorised_zone is not None:
        _wait_for(lambda: zone_guard.pose_diagnostic_known(driver.zone_guard_pose()), system,
                  deadline, lambda: 'the zone guard has no pose to guard the zone with ('
                  f'its /diagnostics: {driver.zone_guard_pose() or "nothing yet"})', 0.05)
    driver.stop_watching_diagnostics()
    if any(isinstance(step, CommandStep) for step in scenario.steps):
        driver.reach_robot_controller(lambda: _check(system))


def _wait_for(ready: Callable[[], bool], system: SystemProcess, deadline: float,
              problem: Callable[[], str], period_s: float) -> None:
    """Poll ready every period_s until true; RuntimeError(problem()) after deadline."""
    while not ready():
        _check(system)
        if time.monotonic() > deadline:
            raise RuntimeError(problem())
        time.sleep(period_s)


def _check(system: SystemProcess) -> None:
    if not system.alive():
        raise SystemDown()
    if INTERRUPTED.is_set():
        raise Interrupted()


def _run_steps(scenario: Scenario, driver, system: SystemProcess, record: RunRecord,
               options: RunOptions, say: Progress) -> None:
    faults = FaultInjector(system, driver, record)
    if options.lockstep:
        driver.join_lockstep(check=lambda: _check(system))
        # The first step starts on a whole simulated second: every periodic timer of the
        # stack (started at time 0) then has the same phase at the start of every run.
        while not driver.holding_time() or not _whole_second(driver.sim_now()):
            _check(system)
            driver.tick()
    try:
        _run_each_step(scenario, driver, system, options, say, record, faults)
    finally:
        faults.finish()
        driver.leave_lockstep()


def _end_aborted_step(record: RunRecord, now_s: Optional[float]) -> None:
    """
    Date the end of a step cut short (Ctrl-C, the system down) at simulated now_s.

    It was recorded as ending where it began ('aborted in 0.0 s', and a run of 0.00 s
    simulated after the robot had driven for many seconds).
    """
    if not record.step_results or now_s is None:
        return
    last = record.step_results[-1]
    if last.outcome == 'aborted' and now_s > last.start_s:
        last.end_s = now_s


def _whole_second(time_s: float) -> bool:
    """Tell whether a simulated time is a whole second (to the microsecond)."""
    return abs(time_s - round(time_s)) < 1e-6


def _run_each_step(scenario: Scenario, driver, system: SystemProcess, options: RunOptions,
                   say: Progress, record: RunRecord, faults: FaultInjector) -> None:
    total = len(scenario.steps)
    for number, step in enumerate(scenario.steps, start=1):
        start_s = driver.sim_now()
        say(f'  step {number}/{total}: {step.describe()}')
        result = StepResult(step.kind, 'aborted', start_s=start_s, end_s=start_s)
        record.step_results.append(result)
        last_status = [start_s]

        def poll() -> float:
            """Check the system, print a status line now and then; return sim now."""
            _check(system)
            now = driver.sim_now()
            faults.due(now)
            if now - last_status[0] >= options.status_period_s:
                last_status[0] = now
                say('    ' + driver.status_line(now - start_s))
            return now

        if isinstance(step, GoalStep):
            _goal(step, driver, result, poll)
        elif isinstance(step, WaypointsStep):
            _waypoints(step, driver, result, poll)
        elif isinstance(step, CommandStep):
            _command(step, driver, result, poll)
        elif isinstance(step, CmdVelStep):
            _cmd_vel(step, driver, result, poll)
        elif isinstance(step, WaitStep):
            _wait(step.duration_s, driver, result, poll)
        elif isinstance(step, (FaultStep, FreezeStep)):
            faults.add(step_fault(step), start_s, number)
            result.outcome = 'done'
        result.end_s = driver.sim_now()
        detail = f' ({error_label(result.error_code)}: {result.error_message})' \
            if result.error_code else ''
        say(f'  step {number}/{total}: {result.outcome}{detail} in '
            f'{result.duration_s:.1f} s')


def _goal(step: GoalStep, driver, result: StepResult, poll) -> None:
    start = driver.latest_truth()
    answer = _action_result(driver.send_goal(step.x, step.y, step.yaw, poll), step.timeout_s,
                            driver, result, poll)
    if answer is None:
        return
    result.error_code, result.error_message = int(answer.error_code), answer.error_msg
    if result.error_code == 0:
        result.outcome = 'reached'
        return
    end = driver.latest_truth()
    moved = math.hypot(end[1] - start[1], end[2] - start[2])
    result.outcome = 'refused' if moved < REFUSED_MOTION_M else 'failed'


def _waypoints(step: WaypointsStep, driver, result: StepResult, poll) -> None:
    answer = _action_result(driver.send_waypoints(step.poses, poll), step.timeout_s,
                            driver, result, poll)
    if answer is None:
        return
    missed = list(answer.missed_waypoints)
    if not missed and answer.error_code == 0:
        result.outcome = 'reached'
        return
    result.outcome = 'failed'
    result.error_code = int(missed[0].error_code) if missed else 9000
    said = [f'waypoint {m.index + 1} missed: {error_label(int(m.error_code))}'
            + (f' ({m.error_msg})' if m.error_msg else '') for m in missed]
    if answer.error_code:
        said.append(f'FollowWaypoints error {int(answer.error_code)}: {answer.error_msg}')
    result.error_message = '; '.join(said)


def _action_result(handle, timeout_s: float, driver, result: StepResult, poll):
    """
    Wait for an action goal's result (None: refused or timed out, recorded in result).

    The result is asked for again every RESULT_REQUEST_S of wall time: like a goal, a
    get_result request can be lost in discovery (its answer goes to a reader the server
    has not matched yet). Seen under a CPU hog in lockstep at max: a goal refused at
    once never got its answer, and its 10 s of simulated time ran out.
    """
    if handle is None or not handle.accepted:
        result.outcome, result.error_code = 'refused', 9000
        result.error_message = 'the goal was rejected'
        return None
    futures = [handle.get_result_async()]
    asked = time.monotonic()
    deadline = result.start_s + timeout_s
    while not any(future.done() for future in futures):
        if poll() > deadline:
            driver.cancel(handle, poll)
            result.outcome = 'timeout'
            return None
        if time.monotonic() - asked > RESULT_REQUEST_S:
            futures.append(handle.get_result_async())
            asked = time.monotonic()
        driver.tick()
    return next(future for future in futures if future.done()).result().result


def _command(step: CommandStep, driver, result: StepResult, poll) -> None:
    statuses = driver.send_command(step.text, poll)
    deadline = result.start_s + step.timeout_s
    accepted = step.motion.is_stop   # 'stop' is answered 'done: stop' at once
    while True:
        for status in statuses():
            # Reports of an earlier motion may still arrive: ours start at 'accepted'.
            if status.startswith('accepted:'):
                accepted = accepted or status.split(':', 1)[1].strip() == step.text.strip()
                continue
            if status.startswith('rejected'):
                result.outcome, result.error_message = 'rejected', status
                return
            if not accepted:
                continue
            if status.startswith('done'):
                result.outcome = 'done'
                return
            if status.startswith('interrupted'):
                result.outcome, result.error_message = 'interrupted', status
                return
            if status.startswith('stopped'):
                result.outcome, result.error_message = 'stopped', status
                return
        if poll() > deadline:
            driver.send_command('stop', poll)
            result.outcome = 'timeout'
            return
        driver.tick()


def _cmd_vel(step: CmdVelStep, driver, result: StepResult, poll) -> None:
    end = result.start_s + step.duration_s
    next_s = result.start_s
    while True:
        now = poll()
        if now >= end:
            break
        if now >= next_s:
            driver.publish_twist(step.vx, step.vy, step.wz, step.topic)
            next_s = now + CMD_VEL_PERIOD_S
        driver.tick()
    driver.publish_twist(0.0, 0.0, 0.0, step.topic)
    result.outcome = 'done'


def _wait(duration_s: float, driver, result: StepResult, poll) -> None:
    while poll() < result.start_s + duration_s:
        driver.tick()
    result.outcome = 'done'


def _plot(scenario: Scenario, record: RunRecord, plans: Sequence[np.ndarray],
          collision_points: Sequence, path_png: Path, verdict: str) -> None:
    from mecanum_map_server.map_io import find_map_file, load_map
    try:
        occupancy = load_map(find_map_file(scenario.map_name))
    except Exception:  # noqa: B902 - a plot without its map is still a plot
        occupancy = None
    goals = scenario.goal_poses
    plot_run(path_png, occupancy, record.truth, record.estimate, plans, goals,
             collision_points, scenario.authorised_zone,
             title=f'{scenario.name}: {verdict}',
             safety_events=[(x, y, text) for _, _, text, x, y in record.safety_events])


# --- the command line --------------------------------------------------------------------

def _worker_init() -> None:
    """Set up a --jobs worker: Ctrl-C (to the whole group) or SIGTERM end its run cleanly."""
    for number in (signal.SIGINT, signal.SIGTERM):
        signal.signal(number, interrupt)


def _run_in_worker(scenario: Scenario, options: RunOptions, quiet: bool) -> ScenarioResult:
    """Run one scenario in a --jobs worker process (progress printed unless quiet)."""
    say = None if quiet else (lambda text: print(text, flush=True))
    return run_scenario(scenario, replace(options, progress=say))


def _run_all(scenarios: Sequence[Scenario], options: RunOptions, jobs: int, quiet: bool,
             say: Progress) -> List[ScenarioResult]:
    """Run the scenarios one at a time, or jobs at once in worker processes."""
    results: List[ScenarioResult] = []

    def report(index: int, scenario: Scenario, result: ScenarioResult) -> None:
        say(f'[{index}/{len(scenarios)}] {scenario.name}: {result.status} '
            f'(verdict {result.verdict.verdict if result.verdict else "none"}, '
            f'expected {scenario.expect}) in {result.wall_time_s or 0:.0f} s; report in '
            f'{options.out_dir / scenario.name}')

    if jobs <= 1:
        try:
            for index, scenario in enumerate(scenarios, start=1):
                if INTERRUPTED.is_set():
                    results.append(ScenarioResult(scenario.name, scenario.expect,
                                                  error='not run (interrupted)'))
                    continue
                say(f'[{index}/{len(scenarios)}] {scenario.name}: {scenario.description}')
                results.append(run_scenario(scenario, options))
                report(index, scenario, results[-1])
        finally:
            release_kept_system()
        return results
    say(f'running {len(scenarios)} scenarios, {jobs} at once')
    # spawn: a fresh interpreter per worker (no forked rclpy or reader threads).
    with ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context('spawn'),
                             initializer=_worker_init) as pool:
        worker_options = replace(options, progress=None, on_system=None)
        futures = [pool.submit(_run_in_worker, scenario, worker_options, quiet)
                   for scenario in scenarios]
        cancelled = False
        for index, (scenario, future) in enumerate(zip(scenarios, futures), start=1):
            while not future.done():
                if INTERRUPTED.is_set() and not cancelled:
                    cancelled = True
                    for pending in futures:
                        pending.cancel()
                    # A SIGTERM came to this process only (Ctrl-C reaches the workers too).
                    for worker in multiprocessing.active_children():
                        os.kill(worker.pid, _INTERRUPTION['signum'])
                time.sleep(0.2)
            if future.cancelled():
                result = ScenarioResult(scenario.name, scenario.expect,
                                        error='not run (interrupted)')
            elif future.exception() is not None:
                error = future.exception()
                result = ScenarioResult(scenario.name, scenario.expect,
                                        error=f'worker error: {type(error).__name__}: {error}')
            else:
                result = future.result()
            results.append(result)
            report(index, scenario, result)
    return results


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Command line entry point; returns the exit code (see the module docstring)."""
    parser = argparse.ArgumentParser(
        prog='run_scenarios', description='Run scenario files with the simulated robot, '
        'headless and isolated, and judge them.')
    parser.add_argument('paths', nargs='+', help='scenario files or folders of them')
    parser.add_argument('--out', default='scenario_results',
                        help='report folder (one subfolder per scenario)')
    parser.add_argument('--junit', help='write the verdicts as JUnit XML to this file')
    parser.add_argument('--real-time-factor', type=parse_real_time_factor,
                        help="override every scenario's real_time_factor: a number, or "
                        "'max' (as fast as the stack answers; needs lockstep)")
    parser.add_argument('--no-lockstep', action='store_true',
                        help='simulated time runs on the wall clock instead of waiting for '
                        'the stack (the default is lockstep)')
    parser.add_argument('--record', action='store_true',
                        help='record every topic to DIR/NAME/bag (MCAP rosbag2)')
    parser.add_argument('--foxglove', action='store_true',
                        help='serve the running system to Foxglove (ws://localhost:8765)')
    parser.add_argument('--cold', action='store_true',
                        help="start every scenario's processes anew (default: a scenario "
                        'reuses those of the one before it in the same process, idle '
                        'between them, with new nodes: warm stacks)')
    parser.add_argument('--no-compose', action='store_true',
                        help='run every node in its own process (default: composed)')
    parser.add_argument('--jobs', type=int, default=1,
                        help='run up to this many scenarios at once (default 1)')
    parser.add_argument('--board', choices=BOARDS,
                        help="override every scenario's board: core (the firmware's core in "
                        'the simulator) or firmware (firmware/main.py as flashed, under '
                        "MicroPython's unix port)")
    parser.add_argument('--quiet', action='store_true', help='print only the table')
    options = parser.parse_args(argv)
    if options.jobs < 1:
        parser.error(f'--jobs must be at least 1, got {options.jobs}')
    if options.real_time_factor == 0.0 and options.no_lockstep:
        parser.error('--real-time-factor max needs lockstep (drop --no-lockstep)')
    scenarios, results = [], []
    try:
        files = [file for path in options.paths for file in find_scenarios(path)]
    except (ScenarioError, OSError) as error:
        print(f'run_scenarios: {error}', file=sys.stderr)
        return 2
    if not files:
        print(f'run_scenarios: no scenario files in {options.paths}', file=sys.stderr)
        return 2
    invalid = False
    for file in files:
        try:
            scenarios.append(load_scenario(file))
        except ScenarioError as error:
            invalid = True
            print(f'run_scenarios: {error}', file=sys.stderr)
            results.append(ScenarioResult(Path(file).stem, 'pass', error=str(error)))
    say = (lambda text: None) if options.quiet else (lambda text: print(text, flush=True))
    run_options = RunOptions(Path(options.out), options.real_time_factor, options.record,
                             options.foxglove, say, compose=not options.no_compose,
                             lockstep=not options.no_lockstep, board=options.board,
                             warm=not options.cold)

    with stopping_cleanly_on_signals():
        results += _run_all(scenarios, run_options, options.jobs, options.quiet, say)
    print(results_table(results))
    if options.junit:
        Path(options.junit).parent.mkdir(parents=True, exist_ok=True)
        Path(options.junit).write_text(junit_xml(results), encoding='utf-8')
    if invalid:
        return 2
    return 0 if all(result.status == 'OK' for result in results) else 1


if __name__ == '__main__':
    sys.exit(main())
