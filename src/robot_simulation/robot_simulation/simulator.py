"""
The simulated robot in its world, stepped in simulated time (pure, no ROS, no I/O).

:class:`Simulation` owns the world (static geometry, moving obstacles, test zone),
the mecanum rigid-body physics with DC motors and roller slip
(:mod:`robot_simulation.physics`), the lidar and IMU models
(:mod:`robot_simulation.sensors`) and the ESP32 board: the firmware's own core
(:mod:`mecanum_control.board_core`) running on the simulated robot
(:class:`RobotPlant`, through :class:`mecanum_control.board_sim.SimulatedBoard`), or
with ``board='firmware'`` the firmware as flashed, main.py under MicroPython, stepped in
lockstep with the physics (:mod:`robot_simulation.firmware_board`); either serves a
pseudo-terminal exactly like the real board's serial port once a line is attached.
Time only advances in :meth:`step`, so a run is deterministic for a given seed
whatever the wall clock does. Call :meth:`Simulation.close` when done (the firmware's
process).

Faults (:mod:`robot_simulation.fault_injection`): :meth:`Simulation.add_fault` schedules
one of the 'simulator' kinds (onset absolute, simulated s); each step takes the onsets
and ends due and injects each fault where it arises: the lidar's output
(:meth:`Simulation.lidar_output`), the board's IMU and encoder counters and its serial
line (board_sim's hardware layer), each wheel's traction (the physics) and the true
pose (kidnap, refused when the robot would land on an obstacle). Each change is queued
in ``fault_changes`` for the caller to log.

Units: SI, REP-103; world frame x east, y north; wheel order FL, FR, RL, RR.
"""

from dataclasses import dataclass, field
import math
from typing import List, Optional, Tuple

from mecanum_control.board_model import to_int32
from mecanum_control.board_params import board_params
from mecanum_control.board_sim import SimulatedBoard
from mecanum_control.robot_config import RobotConfig
import numpy as np
from robot_simulation.fault_injection import (
    FaultChange, FaultSchedule, kidnap_target, NO_EFFECTS, ScanFaults)
from robot_simulation.faults import FaultSpec
from robot_simulation.physics import MecanumPhysics, PhysicsParams
from robot_simulation.sensors import ImuConfig, ImuModel, Lidar, LidarConfig
from robot_simulation.world import World


#: Simulated times this close (s) count as equal when faults start and end (0.15 s is
#: 30 steps of 0.005 s, whose product falls a hair short of 0.05 + 0.1).
FAULT_TIME_EPS_S = 1e-9
#: How close (m, between the edges) a walking person comes to the robot before stopping.
WALKER_GAP_M = 0.15
#: How long (s) a walking person waits for the robot before turning back.
WALKER_PATIENCE_S = 3.0
#: How far (m) a person steps aside from their way to pass a robot, and how fast (m/s).
WALKER_SIDESTEP_M = 0.6
WALKER_SIDESTEP_SPEED_M_S = 0.4
#: The room (m) a person leaves between themselves and a robot they walk past.
WALKER_PASS_GAP_M = 0.1
#: The boards a simulation can run (SimulatorConfig.board).
BOARDS = ('core', 'firmware')


@dataclass(frozen=True)
class SimulatorConfig:
    """Rates and sensor models of a simulation run."""

    physics_rate_hz: float = 200.0
    lidar: LidarConfig = field(default_factory=LidarConfig)
    imu: ImuConfig = field(default_factory=ImuConfig)
    seed: int = 0
    #: Tyre-floor friction coefficient of this floor; 0 keeps the robot's
    #: wheel_friction_coefficient. A low value (0.1: polished tiles) makes the wheels
    #: slip when the robot accelerates harder than about mu * g.
    floor_friction_coefficient: float = 0.0
    #: The board: 'core' (the firmware's core, board_core, in this process) or
    #: 'firmware' (firmware/main.py as flashed under MicroPython's unix port, in
    #: lockstep: robot_simulation.firmware_board).
    board: str = 'core'

    def __post_init__(self) -> None:
        if not (math.isfinite(self.physics_rate_hz) and self.physics_rate_hz >= 50.0):
            raise ValueError(f'physics_rate_hz must be >= 50, got {self.physics_rate_hz}')
        if not (math.isfinite(self.floor_friction_coefficient)
                and self.floor_friction_coefficient >= 0.0):
            raise ValueError('floor_friction_coefficient must be >= 0 (0: the robot '
                             'wheel_friction_coefficient), got '
                             f'{self.floor_friction_coefficient}')
        if self.board not in BOARDS:
            raise ValueError(f'board must be one of {", ".join(BOARDS)}, got {self.board!r}')


class RobotPlant:
    """
    The simulated robot as the board's hardware layer sees it (board_sim's plant).

    ``efforts`` are the duties the firmware applies (-1..1, FL FR RL RR), which the
    physics drives the motors with; the clock is simulated time; the encoder counts
    are the wheel angles in whole quadrature counts; the IMU is the simulation's.
    """

    def __init__(self, simulation: 'Simulation', rad_per_count: float):
        self._sim = simulation
        self.rad_per_count = rad_per_count
        self.efforts: List[float] = [0.0] * 4

    @property
    def time_us(self) -> int:
        """Return simulated time in microseconds."""
        return int(round(self._sim.time_s * 1e6))

    @property
    def ticks(self) -> Tuple[int, int, int, int]:
        """Return the encoder counters (signed 32-bit, wrapping), FL FR RL RR."""
        angles = self._sim.physics.state.wheel_angles_rad
        return tuple(to_int32(math.floor(a / self.rad_per_count)) for a in angles)

    def imu(self) -> Tuple[Tuple[float, float, float], Tuple[float, float, float]]:
        """Return one IMU sample (accel m/s^2, gyro rad/s) of the simulated body."""
        return self._sim.imu_sample()


class Simulation:
    """One robot in one world, advanced one physics step at a time."""

    def __init__(self, world: World, robot: RobotConfig,
                 config: SimulatorConfig = SimulatorConfig()):
        self.world = world
        self.robot = robot
        self.config = config
        self.dt_s = 1.0 / config.physics_rate_hz
        self.time_s = 0.0
        self.steps = 0
        x, y, yaw = world.robot_start
        overrides = {}
        if config.floor_friction_coefficient > 0.0:
            overrides['friction_coefficient'] = config.floor_friction_coefficient
        self.physics = MecanumPhysics(PhysicsParams.from_robot_config(robot, **overrides),
                                      world.segments, x=x, y=y, yaw=yaw)
        self.lidar = Lidar(config.lidar, world.segments, seed=config.seed)
        self.imu_model = ImuModel(config.imu, seed=config.seed + 1)
        # The firmware's own core on the simulated robot (or the firmware as flashed):
        # attach a serial line to serve it.
        plant = RobotPlant(self, robot.rad_per_count)
        if config.board == 'firmware':
            from robot_simulation.firmware_board import FirmwareBoard
            self.board = FirmwareBoard(plant, robot)
        else:
            self.board = SimulatedBoard(plant, board_params(robot))
        self.left_test_zone_count = 0
        self._last_imu_s = 0.0
        self._in_zone = world.in_test_zone(x, y)
        self._static_circles = np.array(
            [(c.center[0], c.center[1], c.radius_m) for c in world.circles],
            dtype=float).reshape(-1, 3)
        # Static rows, then one row per moving obstacle, refreshed once per time step.
        self._circles = np.vstack([self._static_circles, np.array(
            [(0.0, 0.0, m.radius_m) for m in world.moving_obstacles]).reshape(-1, 3)])
        self._circles_time_s = None
        # Each walker's own clock: it stops while the robot stands in its way.
        self._walk_time_s = [0.0] * len(world.moving_obstacles)
        self._walk_direction = [1.0] * len(world.moving_obstacles)
        self._waited_s = [0.0] * len(world.moving_obstacles)
        self._walk_offset = [(0.0, 0.0)] * len(world.moving_obstacles)   # aside, world m
        self.faults = FaultSchedule()
        #: The fault changes not taken yet (the node logs and publishes them).
        self.fault_changes: List[FaultChange] = []
        self._scan_faults = ScanFaults()

    def step(self) -> None:
        """Advance one physics step with the board's duties, then run the board's loop once."""
        self.physics.step(self.board.plant.efforts, self.dt_s, self.all_circles())
        self.steps += 1
        self.time_s = self.steps * self.dt_s
        if self.time_s + FAULT_TIME_EPS_S >= self.faults.next_change_s:
            self._change_faults()
        self._walk(self.dt_s)
        state = self.physics.state
        in_zone = self.world.in_test_zone(state.x, state.y)
        if self._in_zone and not in_zone:
            self.left_test_zone_count += 1
        self._in_zone = in_zone
        self.board.poll()

    def close(self) -> None:
        """Release the board (board 'firmware': stop its firmware's process)."""
        self.board.close()

    def add_fault(self, fault: FaultSpec) -> Optional[str]:
        """
        Schedule a 'simulator' fault (onset absolute, simulated s); None or why it is not.

        Raises FaultError for a kind the simulator does not inject.
        """
        return self.faults.add(fault, self.time_s)

    def _change_faults(self) -> None:
        """Inject the faults acting from now on, apply the instants due, queue the change."""
        change = self.faults.update(self.time_s + FAULT_TIME_EPS_S)
        if change is None:
            return
        effects = change.effects
        self.physics.set_traction_factors(effects.traction_factors)
        hardware = self.board.hw
        hardware.set_stuck_encoders(effects.stuck_wheels)
        hardware.imu_silent = effects.imu_silent
        hardware.imu_bias = effects.imu_bias_sample()
        line = self.board.line
        if line is not None:
            line.set_byte_faults(effects.serial_drop_rate, effects.serial_flip_rate,
                                 effects.serial_latency_s)
        for fault in change.instants:   # kidnap is the only instant the simulator injects
            refused, text = self.kidnap(fault)
            change.outcomes.append((fault, refused, text))
        self.fault_changes.append(change)

    def kidnap(self, fault: FaultSpec) -> Tuple[Optional[str], str]:
        """
        Move the true robot by a kidnap's (dx_m, dy_m, dyaw_rad), keeping its motion.

        Refused (nothing moves) when the footprint there would overlap a wall, furniture
        or a person, or leave the world: the fault asks for a pose, and any other pose
        would be a different fault. Returns (None or the reason refused, a text).
        """
        state = self.physics.state
        x, y, yaw = kidnap_target((state.x, state.y, state.yaw), fault)
        here = f'({state.x:.3f}, {state.y:.3f}, {math.degrees(state.yaw):.1f} deg)'
        there = f'({x:.3f}, {y:.3f}, {math.degrees(yaw):.1f} deg)'
        # 1 mm of slack: a robot touching a wall may be turned where it stands.
        radius = self.robot.footprint_radius_m - 1e-3
        reason = None
        if not self.world.is_free(x, y, radius):
            reason = 'a wall or furniture (or the world edge)'
        else:
            for cx, cy, cr in self.moving_circles():
                if math.hypot(x - cx, y - cy) < radius + cr:
                    reason = 'a person'
                    break
        if reason is not None:
            return reason, (f'refused: the robot at {here} would land on {reason} at '
                            f'{there}; it stays')
        self.physics.move_to(x, y, yaw)
        self._in_zone = self.world.in_test_zone(x, y)
        return None, f'the robot moved from {here} to {there}'

    def _walk(self, dt_s: float) -> None:
        """
        Move each walker on by dt_s, stepping aside for a robot in its way.

        People in a home do not walk into a robot, so a contact with a walker is the
        robot's doing (it drove into the person). In the way: ahead of the walker, less
        than the two radii plus WALKER_PASS_GAP_M off its line, and WALKER_GAP_M from
        touching; a robot
        beside the way does not stop it. A walker with a robot in its way steps aside
        (away from the robot, at WALKER_SIDESTEP_SPEED_M_S, up to WALKER_SIDESTEP_M off
        its path, never into furniture, keeping WALKER_PASS_GAP_M from the robot) and
        walks on past it, then drifts back onto its path. Where there is no room to pass
        (or it is held between the robot and furniture) it waits, and after
        WALKER_PATIENCE_S turns back and walks its path the other way (no one waits for
        ever).
        """
        state = self.physics.state
        robot = (state.x, state.y)
        for index, mover in enumerate(self.world.moving_obstacles):
            step_s = dt_s * self._walk_direction[index]
            base_now = mover.position_at(self._walk_time_s[index])
            base_ahead = mover.position_at(self._walk_time_s[index] + step_s)
            step = math.dist(base_now, base_ahead)
            if step == 0.0:
                self._walk_time_s[index] += step_s
                continue
            direction = ((base_ahead[0] - base_now[0]) / step,
                         (base_ahead[1] - base_now[1]) / step)
            offset = self._walk_offset[index]
            now = (base_now[0] + offset[0], base_now[1] + offset[1])
            ahead = (base_ahead[0] + offset[0], base_ahead[1] + offset[1])
            contact = mover.radius_m + self.robot.footprint_radius_m
            if not self._robot_in_way(now, ahead, direction, contact):
                nearer = self._back_to_path(mover.radius_m, base_ahead, offset, dt_s,
                                            contact)
                # Aside, the way on may be blocked by furniture: back to the path first.
                if nearer == offset and offset != (0.0, 0.0) and not self.world.is_free(
                        base_ahead[0] + offset[0], base_ahead[1] + offset[1], mover.radius_m):
                    back = self._back_to_path(mover.radius_m, base_now, offset, dt_s, contact)
                    if back == offset:   # held between the robot and furniture: wait
                        self._wait(index, dt_s)
                    self._walk_offset[index] = back
                    continue
                self._waited_s[index] = 0.0
                self._walk_time_s[index] += step_s
                self._walk_offset[index] = nearer
                continue
            # Step aside, away from the robot: to the walker's right when the robot is
            # on its left.
            rx, ry = robot[0] - now[0], robot[1] - now[1]
            cross = direction[0] * ry - direction[1] * rx
            side = -1.0 if cross > 0.0 else 1.0
            # Only where there is room to pass: the spot far enough aside is free.
            needed = contact + WALKER_PASS_GAP_M + 0.01 - abs(cross)
            clear = (offset[0] - direction[1] * side * needed,
                     offset[1] + direction[0] * side * needed)
            move = WALKER_SIDESTEP_SPEED_M_S * dt_s * side
            aside = (offset[0] - direction[1] * move, offset[1] + direction[0] * move)
            spot = (base_now[0] + aside[0], base_now[1] + aside[1])
            if (math.hypot(*clear) <= WALKER_SIDESTEP_M + 1e-9
                    and self.world.is_free(base_now[0] + clear[0], base_now[1] + clear[1],
                                           mover.radius_m)
                    and self.world.is_free(spot[0], spot[1], mover.radius_m)
                    and math.dist(spot, robot) >= contact + WALKER_PASS_GAP_M):
                self._walk_offset[index] = aside
                self._waited_s[index] = 0.0
                continue
            self._wait(index, dt_s)

    def _wait(self, index: int, dt_s: float) -> None:
        """Let a walker wait dt_s; after WALKER_PATIENCE_S it turns back."""
        self._waited_s[index] += dt_s
        if self._waited_s[index] >= WALKER_PATIENCE_S:
            self._walk_direction[index] *= -1.0
            self._waited_s[index] = 0.0

    def _robot_in_way(self, now, ahead, direction, contact: float) -> bool:
        """Tell whether the robot stands in the way of a walker stepping from now to ahead."""
        state = self.physics.state
        rx, ry = state.x - now[0], state.y - now[1]
        along = rx * direction[0] + ry * direction[1]
        across = abs(rx * direction[1] - ry * direction[0])
        return (along > 0.0 and across < contact + WALKER_PASS_GAP_M
                and math.dist(ahead, (state.x, state.y)) < contact + WALKER_GAP_M)

    def _back_to_path(self, radius_m: float, base, offset, dt_s: float, contact: float):
        """Return a walker's offset moved back toward its path (if that spot is free)."""
        size = math.hypot(*offset)
        if size == 0.0:
            return offset
        shrink = max(0.0, size - WALKER_SIDESTEP_SPEED_M_S * dt_s) / size
        nearer = (offset[0] * shrink, offset[1] * shrink)
        spot = (base[0] + nearer[0], base[1] + nearer[1])
        state = self.physics.state
        if (self.world.is_free(spot[0], spot[1], radius_m)
                and math.dist(spot, (state.x, state.y)) >= contact + WALKER_PASS_GAP_M):
            return nearer
        return offset

    def moving_circles(self) -> np.ndarray:
        """Return the moving obstacles now, as rows (x, y, radius)."""
        return self.all_circles()[len(self._static_circles):]

    def all_circles(self) -> np.ndarray:
        """Return the static circular obstacles and the moving ones, as rows (x, y, radius)."""
        circles = self._circles
        if self._circles_time_s != self.time_s:
            self._circles_time_s = self.time_s
            row = len(self._static_circles)
            for mover, walk_time_s, offset in zip(self.world.moving_obstacles,
                                                  self._walk_time_s, self._walk_offset):
                x, y = mover.position_at(walk_time_s)
                circles[row, 0], circles[row, 1] = x + offset[0], y + offset[1]
                row += 1
        return circles

    def scan(self) -> np.ndarray:
        """One lidar scan from the current pose (float32 ranges, REP-117)."""
        state = self.physics.state
        return self.lidar.scan(state.x, state.y, state.yaw, self.all_circles())

    def lidar_output(self) -> Optional[np.ndarray]:
        """
        One scan as the lidar outputs it now, with its faults (None: it sends none).

        Stamp it ``faults.effects.scan_stamp_offset_s`` late (scan_stamp_skew).
        """
        ranges = self.scan()
        if self.faults.effects is NO_EFFECTS:
            return ranges
        return self._scan_faults.apply(self.faults.effects, ranges)

    def imu_sample(self) -> Tuple[Tuple[float, float, float], Tuple[float, float, float]]:
        """One IMU sample of the body now (accel m/s^2, gyro rad/s, IMU frame = base_link)."""
        state = self.physics.state
        since_last_s = self.time_s - self._last_imu_s
        self._last_imu_s = self.time_s
        accel, gyro = self.imu_model.sample((state.vx, state.vy, state.wz),
                                            self.physics.body_velocity_rate, since_last_s)
        return tuple(float(a) for a in accel), tuple(float(g) for g in gyro)

    @property
    def in_test_zone(self) -> bool:
        """Tell whether the robot's centre is inside the world's authorised test zone."""
        return self._in_zone

    @property
    def collision_count(self) -> int:
        """Return the number of collisions so far (each new contact counts once)."""
        return self.physics.collision_count
