#!/usr/bin/env python3
"""
Benchmark: real-time factor of the simulator core (no ROS), with ir-sim side by side.

Steps robot_simulation.simulator.Simulation directly (no ROS, no board link, no
pacing) in the apartment world, driving a fixed pattern: body twists forward,
back, strafe left, strafe right, turn left, turn right, 2 s each, turned into
wheel duties with the inverse kinematics and re-commanded at 50 Hz of simulated
time (the board zeroes duties after its command timeout). Every scenario runs for
the same simulated time; the real-time factor (RTF) is simulated seconds per wall
second of the stepping loop (building the Simulation is not timed). Rows:

1. baseline: one robot, 360-beam lidar at 10 Hz, IMU at 100 Hz, physics at 200 Hz
   (goal: RTF >= 100);
2. lidar scaling: 720 and 1440 beams;
3. robot scaling: 2, 4, 8 independent Simulation instances of the same world
   stepped in one loop (the simulator is single-robot: they do not see each other);
4. physics at 500 Hz;
5. a lidar scan after every physics step (200 scans/s), the like-for-like partner
   of ir-sim's default, which scans on every step.

Side by side, ir-sim (https://github.com/hanruihua/ir-sim, a kinematic 2D
simulator) runs an equivalent headless scenario in its own venv, in a subprocess:
one omni-directional robot ('omni_angular' kinematics) with a 360-beam, 12 m
lidar, the apartment's walls and furniture as polygons and circles, the person
walking the same loop, step_time 0.005 s, the same twist pattern; rows with the
lidar at 10 Hz, on every step (ir-sim's own way; 10 s simulated, it is slow), off,
and at ir-sim's usual 0.1 s step (not equivalent, for scale). ir-sim is
optional: it is looked for at --irsim-python and reported as not available when
missing; --setup-irsim creates that venv and pip-installs ir-sim first.

The scenarios are run round-robin --repeats times (so slow drift of the machine
hits them all alike) and the table shows the median wall time of each; compare
the ratios to row 1, measured in the same run.

Run:  ./mecanum exec python bench/simulator_rtf.py [--duration 60] [--repeats 3]
      ./mecanum exec python bench/simulator_rtf.py --setup-irsim   (once, for ir-sim)
Prints a table; --json FILE also writes the numbers.
"""

import argparse
from dataclasses import dataclass
import json
import math
import os
from pathlib import Path
import statistics
import subprocess
import sys
import tempfile
import time
from typing import Dict, List, Optional

DEFAULT_IRSIM_PYTHON = Path('/tmp/irsim-venv/bin/python')
#: What --setup-irsim installs (the version this script was written against).
DEFAULT_IRSIM_SPEC = 'ir-sim==2.12.0'
#: Body twists (vx m/s, vy m/s, wz rad/s) of the drive pattern, SEGMENT_S each, in a loop.
#: Each motion is followed by its opposite, so the robot stays in the living room.
PATTERN = ((0.4, 0.0, 0.0), (-0.4, 0.0, 0.0), (0.0, 0.4, 0.0), (0.0, -0.4, 0.0),
           (0.0, 0.0, 1.0), (0.0, 0.0, -1.0))
SEGMENT_S = 2.0
#: Rate (simulated) at which the driver re-commands the board (velocity_controller's rate).
COMMAND_RATE_HZ = 50.0
IMU_RATE_HZ = 100.0
LIDAR_RATE_HZ = 10.0
BASELINE_GOAL_RTF = 100.0
#: Simulated seconds of the ir-sim row that scans on every 5 ms step (~0.7 s wall each).
IRSIM_EVERY_STEP_S = 10.0
#: A start-pose beam of ir-sim and of the core agreeing within this (m) counts as the same.
SCAN_AGREEMENT_M = 0.05
TIME_EPS = 1e-9

# Runs in ir-sim's venv (python -c), argv[1] a JSON spec; prints one JSON line on stdout.
# ir-sim picks a matplotlib backend when imported (TkAgg first); the caller clears
# DISPLAY and sets MPLBACKEND=Agg, and headless=True builds no figure at all.
IRSIM_DRIVER = """
import contextlib
import json
import sys
import time

with contextlib.redirect_stdout(sys.stderr):
    import matplotlib
    matplotlib.use('Agg')
    import irsim
    matplotlib.use('Agg')
    import numpy as np

spec = json.loads(sys.argv[1])
actions = [np.array([[vx], [vy], [wz]], dtype=float) for vx, vy, wz in spec['pattern']]
out = {'version': irsim.__version__, 'backend': matplotlib.get_backend(),
       'numpy': np.__version__, 'results': []}
for scenario in spec['scenarios']:
    with contextlib.redirect_stdout(sys.stderr):
        env = irsim.make(scenario['world'], headless=True, display=False, log_level='WARNING',
                         seed=0)
    robot = env.robot
    lidars = list(robot.sensors)
    if 'start_scan' not in out:  # taken when the env is made, at the start pose
        out['start_scan'] = {'angle_min': float(robot.lidar.angle_min),
                             'ranges': [float(r) for r in robot.lidar.range_data],
                             'valid': [bool(v) for v in robot.lidar.valid]}
    dt = env.step_time
    steps = int(round(scenario['duration_s'] / dt))
    lidar_hz = scenario['lidar_hz']  # None: a scan on every step (ir-sim's way); 0: none
    command_period = 1.0 / spec['command_rate_hz']
    next_command = next_scan = 0.0
    scans = 0
    action = actions[0]
    start = time.perf_counter()
    for k in range(steps):
        now = k * dt
        if now + 1e-9 >= next_command:
            next_command += command_period
            action = actions[int(now / spec['segment_s'] + 1e-9) % len(actions)]
        due = lidar_hz is None
        if lidar_hz and (k + 1) * dt + 1e-9 >= next_scan:
            next_scan += 1.0 / lidar_hz
            due = True
        robot.sensors = lidars if due else []
        env.step(action)
        scans += due
    wall = time.perf_counter() - start
    robot.sensors = lidars
    person = env.get_object_by_name('person')
    out['results'].append({
        'name': scenario['name'], 'sim_s': steps * dt, 'wall_s': wall, 'scans': scans,
        'irsim_time_s': float(env.time),
        'final_pose': [float(v) for v in robot.state[:3, 0]],
        'robot_stopped': bool(robot.stop_flag), 'robot_collided': bool(robot.collision_flag),
        'person_stopped': bool(person.stop_flag) if person is not None else None,
        'valid_beams_last_scan': int(robot.lidar.valid.sum())})
    with contextlib.redirect_stdout(sys.stderr):
        env.end(0)
print(json.dumps(out))
"""


@dataclass(frozen=True)
class CoreScenario:
    """One configuration of the simulator core to time."""

    name: str
    robots: int = 1
    beams: int = 360
    physics_hz: float = 200.0
    lidar_hz: Optional[float] = LIDAR_RATE_HZ  # None: a scan after every physics step


def core_scenarios() -> List[CoreScenario]:
    """Return the core rows, baseline first."""
    return [
        CoreScenario(f'baseline (goal >= {BASELINE_GOAL_RTF:.0f}x): 1 robot, 360 beams @10 Hz,'
                     ' IMU 100 Hz, physics 200 Hz'),
        CoreScenario('lidar 720 beams', beams=720),
        CoreScenario('lidar 1440 beams', beams=1440),
        CoreScenario('2 robots (independent, one loop)', robots=2),
        CoreScenario('4 robots (independent, one loop)', robots=4),
        CoreScenario('8 robots (independent, one loop)', robots=8),
        CoreScenario('physics 500 Hz', physics_hz=500.0),
        CoreScenario('lidar scan every physics step (200 scans/s)', lidar_hz=None),
    ]


def irsim_scenarios(fine_world: Path, coarse_world: Path, duration_s: float) -> List[dict]:
    """Return the ir-sim rows (the driver's spec entries); the slow one runs a shorter time."""
    short_s = min(duration_s, IRSIM_EVERY_STEP_S)
    return [
        {'name': 'ir-sim: 1 omni robot, 360 beams @10 Hz, step 0.005 s', 'lidar_hz': LIDAR_RATE_HZ,
         'world': str(fine_world), 'duration_s': duration_s},
        {'name': f'ir-sim: same, lidar every step (200 scans/s, its default; {short_s:g} s)',
         'lidar_hz': None, 'world': str(fine_world), 'duration_s': short_s},
        {'name': 'ir-sim: same, no lidar (kinematics + collision checks)', 'lidar_hz': 0.0,
         'world': str(fine_world), 'duration_s': duration_s},
        {'name': 'ir-sim, NOT equivalent: its usual step 0.1 s, lidar every step (10 Hz)',
         'lidar_hz': None, 'world': str(coarse_world), 'duration_s': duration_s},
    ]


def pattern_duties(robot) -> List[List[float]]:
    """Return the wheel duties (FL FR RL RR, -1..1) of each twist of PATTERN."""
    from mecanum_control.kinematics import inverse_kinematics

    duties = []
    for vx, vy, wz in PATTERN:
        speeds = inverse_kinematics(robot.geometry, vx, vy, wz)
        duties.append([max(-1.0, min(1.0, w / robot.motor_no_load_speed_rad_s))
                       for w in speeds])
    return duties


def run_core(scenario: CoreScenario, world, robot, duration_s: float) -> dict:
    """Step `scenario` for duration_s simulated seconds; return its timing and sanity data."""
    from robot_simulation.sensors import ImuConfig, LidarConfig
    from robot_simulation.simulator import Simulation, SimulatorConfig

    lidar_rate = scenario.lidar_hz if scenario.lidar_hz else scenario.physics_hz
    sims = [Simulation(world, robot, SimulatorConfig(
        physics_rate_hz=scenario.physics_hz,
        lidar=LidarConfig(beams=scenario.beams, rate_hz=lidar_rate),
        imu=ImuConfig(rate_hz=IMU_RATE_HZ), seed=index)) for index in range(scenario.robots)]
    duties = pattern_duties(robot)
    timeout_ms = robot.board_command_timeout_ms
    steps = int(round(duration_s * scenario.physics_hz))
    command_period = 1.0 / COMMAND_RATE_HZ
    scan_period = 1.0 / scenario.lidar_hz if scenario.lidar_hz else 0.0
    imu_period = 1.0 / IMU_RATE_HZ
    next_command = next_scan = next_imu = 0.0
    seq = scans = 0
    lead = sims[0]
    start = time.perf_counter()
    for _ in range(steps):
        now = lead.time_s
        if now + TIME_EPS >= next_command:
            next_command += command_period
            seq += 1
            command = duties[int(now / SEGMENT_S + TIME_EPS) % len(duties)]
            for sim in sims:
                sim.board.command(command, timeout_ms, seq)
        for sim in sims:
            sim.step()
        now = lead.time_s
        if now + TIME_EPS >= next_scan:
            next_scan += scan_period
            scans += 1
            for sim in sims:
                sim.scan()
        if now + TIME_EPS >= next_imu:
            next_imu += imu_period
            for sim in sims:
                sim.imu_sample()
    wall = time.perf_counter() - start
    state = lead.physics.state
    return {'sim_s': lead.time_s, 'wall_s': wall, 'scans_per_robot': scans,
            'collisions': sum(sim.collision_count for sim in sims),
            'final_pose': [state.x, state.y, state.yaw]}


def irsim_world(world, robot, beams: int, step_time_s: float) -> dict:
    """Return an ir-sim world document equivalent to `world` (static obstacles + movers)."""
    xmin, ymin, xmax, ymax = world.bounds
    x, y, yaw = world.robot_start
    obstacles = []
    for obstacle in world.obstacles:
        if obstacle.kind == 'circle':  # kept exact below
            continue
        obstacles.append({'name': obstacle.name, 'state': [0.0, 0.0, 0.0],
                          'shape': {'name': 'polygon',
                                    'vertices': [[float(px), float(py)]
                                                 for px, py in obstacle.polygon]}})
    for circle in world.circles:
        obstacles.append({'name': circle.name,
                          'state': [float(circle.center[0]), float(circle.center[1]), 0.0],
                          'shape': {'name': 'circle', 'radius': float(circle.radius_m)}})
    for mover in world.moving_obstacles:
        path = [[float(px), float(py), 0.0] for px, py in mover.path]
        goals = path[1:] + path[:1] if mover.loop else path[1:]
        obstacles.append({
            'name': mover.name, 'state': path[0], 'kinematics': {'name': 'omni'},
            'shape': {'name': 'circle', 'radius': float(mover.radius_m)},
            'vel_max': [mover.speed_m_s, mover.speed_m_s],
            'vel_min': [-mover.speed_m_s, -mover.speed_m_s],
            'goal': goals, 'behavior': {'name': 'dash', 'loop': True}})
    # ir-sim spaces beams with linspace over angle_range (both ends included): this range
    # gives the same 2 pi / beams spacing as the core's lidar.
    angle_range = 2.0 * math.pi * (beams - 1) / beams
    return {
        'world': {'width': xmax - xmin, 'height': ymax - ymin,
                  'offset': [xmin, ymin], 'step_time': step_time_s,
                  'collision_mode': 'stop', 'control_mode': 'auto'},
        'robot': [{
            'name': 'robot', 'kinematics': {'name': 'omni_angular'},
            'shape': {'name': 'circle', 'radius': robot.footprint_radius_m},
            'state': [x, y, yaw],
            'vel_max': [robot.max_velocity_x_m_s, robot.max_velocity_y_m_s,
                        robot.max_angular_velocity_rad_s],
            'vel_min': [-robot.max_velocity_x_m_s, -robot.max_velocity_y_m_s,
                        -robot.max_angular_velocity_rad_s],
            'sensors': [{'name': 'lidar2d', 'range_min': 0.15, 'range_max': 12.0,
                         'angle_range': angle_range, 'number': beams,
                         'noise': True, 'std': 0.01}]}],
        'obstacle': obstacles,
    }


def irsim_environment() -> Dict[str, str]:
    """Return a clean environment for ir-sim's venv: none of this workspace's paths."""
    keep = ('HOME', 'LANG', 'LC_ALL', 'PATH', 'TMPDIR', 'USER')
    env = {name: os.environ[name] for name in keep if name in os.environ}
    env.update(PYTHONNOUSERSITE='1', MPLBACKEND='Agg', PYTHONDONTWRITEBYTECODE='1')
    return env


def setup_irsim(python: Path, spec: str) -> None:
    """Create the venv of `python` (.../bin/python) and pip-install ir-sim into it."""
    venv = python.parent.parent
    env = irsim_environment()
    if not python.exists():
        print(f'creating {venv} ...', flush=True)
        subprocess.run([sys.executable, '-m', 'venv', str(venv)], check=True, env=env)
    print(f'pip install {spec} into {venv} ...', flush=True)
    subprocess.run([str(python), '-m', 'pip', 'install', '--disable-pip-version-check',
                    '--quiet', spec], check=True, env=env)


def run_irsim(python: Path, scenarios: List[dict], timeout_s: float) -> dict:
    """Run the ir-sim scenarios in ir-sim's venv; return the driver's JSON or raise."""
    spec = {'pattern': PATTERN, 'segment_s': SEGMENT_S, 'command_rate_hz': COMMAND_RATE_HZ,
            'scenarios': scenarios}
    done = subprocess.run([str(python), '-c', IRSIM_DRIVER, json.dumps(spec)],
                          env=irsim_environment(), capture_output=True, text=True,
                          timeout=timeout_s)
    lines = done.stdout.strip().splitlines()
    if done.returncode != 0 or not lines:
        tail = (done.stderr.strip().splitlines() or ['no output'])[-1]
        raise RuntimeError(f'ir-sim driver exited with {done.returncode}: {tail}')
    return json.loads(lines[-1])


def scan_agreement(world, start_scan: dict) -> dict:
    """
    Compare ir-sim's first scan (start pose, t = 0) with the core's lidar cast the same way.

    A noise-free core lidar with ir-sim's beam angles, the moving obstacles at t = 0: beams
    valid in both should agree within ir-sim's 1 cm noise if the worlds are the same.
    """
    import numpy as np
    from robot_simulation.sensors import Lidar, LidarConfig

    ranges = np.array(start_scan['ranges'])
    valid = np.array(start_scan['valid'], dtype=bool)
    angle_min = start_scan['angle_min']
    lidar = Lidar(LidarConfig(beams=ranges.size, range_min_m=0.15, range_max_m=12.0,
                              angle_min_rad=angle_min, angle_max_rad=angle_min + 2.0 * math.pi,
                              noise_stddev_m=0.0), world.segments)
    circles = [(c.center[0], c.center[1], c.radius_m) for c in world.circles]
    circles += [(*m.position_at(0.0), m.radius_m) for m in world.moving_obstacles]
    x, y, yaw = world.robot_start
    core = lidar.scan(x, y, yaw, np.array(circles, dtype=float).reshape(-1, 3))
    both = valid & np.isfinite(core)
    diff = np.abs(core[both] - ranges[both])
    return {'beams': int(ranges.size), 'valid_in_both': int(both.sum()),
            'valid_in_one_only': int((valid != np.isfinite(core)).sum()),
            'median_abs_diff_m': float(np.median(diff)) if diff.size else math.nan,
            'beyond_tolerance': int((diff > SCAN_AGREEMENT_M).sum())}


def irsim_unavailable_reason(python: Path) -> Optional[str]:
    """Return why ir-sim cannot be used from `python`, or None when it imports."""
    if not python.exists():
        return f'no {python}; run with --setup-irsim'
    try:
        done = subprocess.run(
            [str(python), '-c', 'import irsim, matplotlib; print(irsim.__version__)'],
            env=irsim_environment(), capture_output=True, text=True, timeout=120)
    except (OSError, subprocess.TimeoutExpired) as error:
        return f'{python} does not run: {error}'
    if done.returncode != 0:
        tail = (done.stderr.strip().splitlines() or ['no output'])[-1]
        return f'import irsim failed in {python}: {tail}'
    return None


def median_row(name: str, runs: List[dict], robots: int = 1) -> dict:
    """Return the summary of the repeats of one scenario (median wall time)."""
    walls = [run['wall_s'] for run in runs]
    wall = statistics.median(walls)
    sim_s = runs[0]['sim_s']
    return {'name': name, 'robots': robots, 'sim_s': sim_s, 'wall_s': wall,
            'wall_s_runs': walls, 'rtf': sim_s / wall, 'rtf_x_robots': robots * sim_s / wall,
            'last_run': runs[-1]}


def main() -> int:
    """Run the benchmark and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--duration', type=float, default=60.0,
                        help='simulated seconds per scenario (default 60)')
    parser.add_argument('--repeats', type=int, default=3,
                        help='runs of each scenario; the table shows the median (default 3)')
    parser.add_argument('--irsim-python', type=Path, default=DEFAULT_IRSIM_PYTHON,
                        help=f'python of the venv holding ir-sim (default {DEFAULT_IRSIM_PYTHON})')
    parser.add_argument('--setup-irsim', action='store_true',
                        help='create that venv and pip-install ir-sim into it first')
    parser.add_argument('--irsim-spec', default=DEFAULT_IRSIM_SPEC,
                        help=f'what --setup-irsim installs (default {DEFAULT_IRSIM_SPEC})')
    parser.add_argument('--no-irsim', action='store_true', help='skip ir-sim')
    parser.add_argument('--json', type=Path)
    args = parser.parse_args()
    if not (args.duration > 0 and args.repeats >= 1):
        parser.error('--duration must be > 0 and --repeats >= 1')

    from mecanum_control.robot_config import default_config_path, load_robot_config
    from robot_simulation.world import find_world, load_world

    robot = load_robot_config(default_config_path())
    world = load_world(find_world('apartment'))

    irsim_reason = 'skipped (--no-irsim)' if args.no_irsim else None
    if args.setup_irsim and not args.no_irsim:
        try:
            setup_irsim(args.irsim_python, args.irsim_spec)
        except (OSError, subprocess.CalledProcessError) as error:
            irsim_reason = f'setup failed: {error}'
    if irsim_reason is None:
        irsim_reason = irsim_unavailable_reason(args.irsim_python)

    scenarios = core_scenarios()
    core_runs: List[List[dict]] = [[] for _ in scenarios]
    irsim_info: dict = {}
    with tempfile.TemporaryDirectory(prefix='simulator_rtf_') as tmp:
        fine_world = Path(tmp) / 'apartment_irsim_5ms.yaml'
        coarse_world = Path(tmp) / 'apartment_irsim_100ms.yaml'
        for path, step_time in ((fine_world, 1.0 / scenarios[0].physics_hz), (coarse_world, 0.1)):
            path.write_text(json.dumps(irsim_world(world, robot, 360, step_time),  # JSON is YAML
                                       indent=1))
        irsim_objects = 1 + len(irsim_world(world, robot, 360, 0.1)['obstacle'])
        irsim_specs = irsim_scenarios(fine_world, coarse_world, args.duration)
        irsim_runs: List[List[dict]] = [[] for _ in irsim_specs]
        # Warm-up (imports, first allocations), not counted.
        run_core(scenarios[0], world, robot, min(args.duration, 2.0))
        for repeat in range(args.repeats):
            print(f'round {repeat + 1}/{args.repeats} ...', file=sys.stderr, flush=True)
            for index, scenario in enumerate(scenarios):
                core_runs[index].append(run_core(scenario, world, robot, args.duration))
            if irsim_reason is None:
                try:
                    result = run_irsim(args.irsim_python, irsim_specs,
                                       timeout_s=120.0 + 20.0 * args.duration)
                except (OSError, RuntimeError, ValueError, subprocess.TimeoutExpired) as error:
                    irsim_reason = f'run failed: {error}'
                else:
                    irsim_info = {k: v for k, v in result.items() if k != 'results'}
                    for index, run in enumerate(result['results']):
                        irsim_runs[index].append(run)

    rows = [median_row(s.name, runs, s.robots) for s, runs in zip(scenarios, core_runs)]
    agreement = None
    if irsim_reason is None:
        rows += [median_row(s['name'], runs) for s, runs in zip(irsim_specs, irsim_runs)]
        agreement = scan_agreement(world, irsim_info.pop('start_scan'))
    base_rtf = rows[0]['rtf']
    for row in rows:
        row['rtf_vs_row1'] = row['rtf'] / base_rtf

    print(f'\nSimulator real-time factor (simulated s / wall s), world apartment, '
          f'{args.duration:g} s simulated per row, median of {args.repeats} runs, '
          f'{os.cpu_count()} CPUs\n')
    header = (f'{"#":>2}  {"scenario":<78} {"sim s":>7} {"wall s":>8} {"RTF":>8} '
              f'{"vs 1":>6} {"RTF x robots":>13}')
    print(header)
    print('-' * len(header))
    for number, row in enumerate(rows, 1):
        if number == len(scenarios) + 1:
            print(f'{"":>2}  ir-sim {irsim_info.get("version", "?")} (separate venv, '
                  f'subprocess, matplotlib backend {irsim_info.get("backend", "?")}, '
                  f'headless)')
        print(f'{number:>2}  {row["name"]:<78} {row["sim_s"]:>7.1f} {row["wall_s"]:>8.3f} '
              f'{row["rtf"]:>7.1f}x {row["rtf_vs_row1"]:>6.2f} {row["rtf_x_robots"]:>12.1f}x')
    if irsim_reason is not None:
        print(f'{"":>2}  ir-sim: not available ({irsim_reason})')
    print()
    verdict = 'met' if base_rtf >= BASELINE_GOAL_RTF else 'NOT met'
    print(f'baseline goal RTF >= {BASELINE_GOAL_RTF:.0f}x: {verdict} ({base_rtf:.1f}x)')
    every = next(i for i, s in enumerate(scenarios) if s.lidar_hz is None)
    base_run, every_run = rows[0], rows[every]
    scans = (base_run['last_run']['scans_per_robot'], every_run['last_run']['scans_per_robot'])
    per_scan_s = (every_run['wall_s'] - base_run['wall_s']) / (scans[1] - scans[0])
    lidar_s = per_scan_s * scans[0]
    if 0.0 < lidar_s < base_run['wall_s']:
        steps = round(base_run['sim_s'] * scenarios[0].physics_hz)
        per_step_us = (base_run['wall_s'] - lidar_s) / steps * 1e6
        print(f'baseline split (rows 1 and {every + 1}): ~{per_scan_s * 1e3:.2f} ms per '
              f'{scenarios[0].beams}-beam scan, ~{per_step_us:.0f} us per physics step (with '
              f'IMU and driving);\n  the lidar is ~{100 * lidar_s / base_run["wall_s"]:.0f}% '
              f'of row 1')
    collisions = {row['name']: row['last_run']['collisions'] for row in rows[:len(scenarios)]
                  if row['last_run']['collisions']}
    if collisions:
        print(f'WARNING: the pattern collided (the timing includes contacts): {collisions}')
    print('Robots rows: independent Simulation instances of the same world stepped in one loop;'
          '\n  the simulator is single-robot, so they do not see each other (no lidar returns,'
          '\n  no contacts between them). "RTF x robots" = robot-seconds simulated per wall s.')
    print('Core: mecanum rigid body with DC motors (lag), roller slip and contacts; ray-cast lidar'
          '\n  (10 Hz unless stated) and IMU at 100 Hz; driven through the board model (duties).')
    if irsim_reason is None:
        stopped = [row['name'] for row in rows[len(scenarios):]
                   if row['last_run']['robot_stopped']]
        if stopped:
            print(f'WARNING: the ir-sim robot collided and stopped in: {stopped}')
        print(f'World check, start pose: the ir-sim scan vs the core lidar cast noise-free along'
              f'\n  the same beams: {agreement["valid_in_both"]}/{agreement["beams"]} valid in '
              f'both, median |diff| {agreement["median_abs_diff_m"] * 100:.1f} cm (ir-sim noise'
              f'\n  1 cm), {agreement["beyond_tolerance"]} beyond {SCAN_AGREEMENT_M * 100:.0f} '
              f'cm, {agreement["valid_in_one_only"]} valid in one only.')
        print('ir-sim: kinematic omni_angular robot (commanded twist applied at once: no motor'
              '\n  lag, no slip, no dynamics), collision_mode stop; every wall and piece of'
              f'\n  furniture is an object of its own ({irsim_objects} objects, each checked in'
              ' Python every step);'
              '\n  its lidar intersects rays with the shapely geometry an STRtree query finds and'
              '\n  runs on every env.step (the 10 Hz rows detach it on the other steps); no IMU;'
              '\n  the person is a dash obstacle looping the same waypoints; timed: env.step.')
    if args.json:
        args.json.write_text(json.dumps({
            'duration_s': args.duration, 'repeats': args.repeats, 'cpus': os.cpu_count(),
            'baseline_goal_rtf': BASELINE_GOAL_RTF, 'rows': rows,
            'irsim': (dict(irsim_info, start_scan_agreement=agreement) if irsim_reason is None
                      else {'not_available': irsim_reason}),
        }, indent=2))
    return 0


if __name__ == '__main__':
    sys.exit(main())
