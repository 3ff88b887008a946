"""Tests of the simulation core: the simulated board, determinism, zones and collisions."""

import math
from pathlib import Path
import textwrap

from mecanum_control.board_model import to_int32
from mecanum_control.esp32_protocol import FaultFlags
from mecanum_control.robot_config import default_config_path, load_robot_config
import numpy as np
import pytest
from robot_simulation.sensors import ImuConfig, LidarConfig
from robot_simulation.simulator import Simulation, SimulatorConfig
from robot_simulation.world import find_world, load_world

ROBOT = load_robot_config(default_config_path())


def box_world(tmp_path: Path, zone: str = '') -> Path:
    """Write a 4 m x 3 m empty room, robot at (1, 1.5) facing +x, optional test zone."""
    path = tmp_path / 'box.yaml'
    path.write_text(textwrap.dedent(f"""
        world:
          name: box
          bounds_m: [0.0, 0.0, 4.0, 3.0]
          {zone}
          robot_start: {{x_m: 1.0, y_m: 1.5, yaw_deg: 0.0}}
        """))
    return path


def quiet_config(seed: int = 0) -> SimulatorConfig:
    """Sensors without noise or bias, for hand-worked numbers."""
    return SimulatorConfig(
        lidar=LidarConfig(noise_stddev_m=0.0),
        imu=ImuConfig(gyro_noise_stddev_rad_s=0.0, gyro_bias_stddev_rad_s=0.0,
                      accel_noise_stddev_m_s2=0.0, accel_bias_stddev_m_s2=0.0),
        seed=seed)


def drive(sim: Simulation, duties, seconds: float) -> None:
    """Command duties every 0.1 s of simulated time (within the board timeout)."""
    for step in range(int(round(seconds / sim.dt_s))):
        if step % 20 == 0:
            sim.board.command(duties, 250, step)
        sim.step()


def test_to_int32_hand_cases():
    """Counters wrap like a signed 32-bit register."""
    assert to_int32(2 ** 31) == -2 ** 31
    assert to_int32(-2 ** 31 - 1) == 2 ** 31 - 1
    assert to_int32(5) == 5


def test_board_is_in_command_timeout_from_boot_and_does_not_move(tmp_path):
    """Without commands the duties are zero and COMMAND_TIMEOUT is set."""
    sim = Simulation(load_world(box_world(tmp_path)), ROBOT, quiet_config())
    for _ in range(100):
        sim.step()
    assert sim.board.faults & FaultFlags.COMMAND_TIMEOUT
    assert sim.physics.state.x == pytest.approx(1.0)


def test_board_stops_the_wheels_when_commands_stop(tmp_path):
    """After 250 ms without a command the duties drop to zero and the robot stops."""
    sim = Simulation(load_world(box_world(tmp_path)), ROBOT, quiet_config())
    sim.board.command([0.3] * 4, 250, 1)
    for _ in range(40):  # 0.2 s: within the timeout
        sim.step()
    assert sim.board.efforts == [0.3] * 4 and not sim.board.faults
    for _ in range(20):  # 0.3 s in all: past it
        sim.step()
    assert sim.board.efforts == [0.0] * 4
    assert sim.board.faults & FaultFlags.COMMAND_TIMEOUT
    for _ in range(200):
        sim.step()
    assert abs(sim.physics.state.vx) < 1e-6


def test_ticks_are_the_wheel_angles_in_whole_counts(tmp_path):
    """Counts = floor(angle / (2 pi / 1320)) for each wheel."""
    sim = Simulation(load_world(box_world(tmp_path)), ROBOT, quiet_config())
    drive(sim, [0.2] * 4, 0.5)
    angles = sim.physics.state.wheel_angles_rad
    expected = tuple(math.floor(a / (2 * math.pi / 1320)) for a in angles)
    assert sim.board.ticks == expected
    assert all(t > 0 for t in expected)


def test_same_seed_same_run_and_another_seed_other_noise(tmp_path):
    """Two runs with one seed give identical poses, scans and IMU samples."""
    world = load_world(find_world('apartment'))

    def run(seed):
        sim = Simulation(world, ROBOT, SimulatorConfig(seed=seed))
        drive(sim, [0.4, 0.2, 0.4, 0.2], 1.0)
        state = sim.physics.state
        return (state.x, state.y, state.yaw), sim.scan(), sim.imu_sample()
    first, second, other = run(3), run(3), run(4)
    assert first[0] == second[0]
    assert np.array_equal(first[1], second[1]) and first[2] == second[2]
    assert not np.array_equal(first[1], other[1])


def test_lidar_in_the_box_room_reads_the_wall_distance(tmp_path):
    """From (1, 1.5) facing +x the east wall (x = 4) is 3 m ahead, the west one 1 m behind."""
    sim = Simulation(load_world(box_world(tmp_path)), ROBOT, quiet_config())
    ranges = sim.scan()
    increment = 2 * math.pi / 360
    ahead = round(math.pi / increment)  # beams start at -pi
    assert ranges[ahead] == pytest.approx(3.0, abs=1e-5)
    assert ranges[0] == pytest.approx(1.0, abs=1e-5)


def test_driving_into_a_wall_stops_there_and_counts_one_collision(tmp_path):
    """Full speed at the east wall: the centre stops 0.2 m (footprint) from it, once."""
    sim = Simulation(load_world(box_world(tmp_path)), ROBOT, quiet_config())
    drive(sim, [0.5] * 4, 12.0)
    assert sim.physics.state.x == pytest.approx(4.0 - ROBOT.footprint_radius_m, abs=1e-3)
    assert sim.collision_count == 1


def test_leaving_the_test_zone_is_counted(tmp_path):
    """The zone covers x < 2: driving east leaves it once."""
    zone = 'test_zone: [[0.1, 0.1], [2.0, 0.1], [2.0, 2.9], [0.1, 2.9]]'
    sim = Simulation(load_world(box_world(tmp_path, zone)), ROBOT, quiet_config())
    assert sim.in_test_zone
    drive(sim, [0.4] * 4, 4.0)
    assert not sim.in_test_zone
    assert sim.left_test_zone_count == 1


def test_a_slippery_floor_limits_acceleration_to_its_friction(tmp_path):
    """Full duty on a mu = 0.1 floor: (mu - C_rr) g acceleration, the wheels spin ahead."""
    config = SimulatorConfig(imu=quiet_config().imu, floor_friction_coefficient=0.1)
    sim = Simulation(load_world(box_world(tmp_path)), ROBOT, config)
    drive(sim, [1.0] * 4, 0.2)
    # Traction mu m g against rolling resistance 0.01 m g: 0.09 * 9.80665 * 0.2 s.
    assert sim.physics.state.vx == pytest.approx(0.09 * 9.80665 * 0.2, rel=0.02)
    rim_speed = ROBOT.geometry.wheel_radius_m * np.mean(sim.physics.state.wheel_speeds_rad_s)
    assert rim_speed > 2.0 * sim.physics.state.vx  # roller slip: odometry would overshoot
    grippy = Simulation(load_world(box_world(tmp_path)), ROBOT, quiet_config())
    drive(grippy, [1.0] * 4, 0.2)
    assert grippy.physics.state.vx > 2.0 * sim.physics.state.vx


def test_floor_friction_must_be_a_non_negative_number():
    for value in (-0.1, math.nan, math.inf):
        with pytest.raises(ValueError, match='floor_friction_coefficient'):
            SimulatorConfig(floor_friction_coefficient=value)


def walk_world(tmp_path, height_m):
    """Write a world bounds x 0..6, y 0..height_m with a person walking from x 4.5 to 0.5."""
    path = tmp_path / 'walk.yaml'
    middle = height_m / 2
    path.write_text(textwrap.dedent(f"""
        world:
          name: walk
          bounds_m: [0.0, 0.0, 6.0, {height_m}]
          moving_obstacles:
          - {{name: person, radius_m: 0.25, speed_m_s: 0.8,
             path: [[4.5, {middle}], [0.5, {middle}]], loop: false}}
          robot_start: {{x_m: 5.5, y_m: {middle}, yaw_deg: 0.0}}
        """))
    return load_world(path)


def run_for(sim, seconds, track=None):
    """Step sim for seconds; append (person x, y, distance to the robot) to track."""
    for _ in range(int(round(seconds / sim.dt_s))):
        sim.step()
        if track is not None:
            x, y, _ = sim.moving_circles()[0]
            state = sim.physics.state
            track.append((x, y, math.hypot(x - state.x, y - state.y)))


def test_a_walking_person_steps_round_a_robot_in_the_way(tmp_path):
    """In a 3 m wide room a person meets the robot on their way, steps aside and walks on."""
    world = walk_world(tmp_path, 3.0)
    sim = Simulation(world, ROBOT, quiet_config())
    sim.physics.teleport(2.0, 1.5, 0.0)   # onto the way (a world file may not start there)
    track = []
    run_for(sim, 8.0, track)
    xs, ys, distances = np.array(track).T
    # Past the robot (x 2.0) and back on the path (y 1.5) at its far end (x 0.5) ...
    assert np.min(xs) == pytest.approx(0.5, abs=0.01)
    assert np.any(np.abs(ys[xs < 1.0] - 1.5) < 1e-9)
    # ... having stepped aside by at least the two radii, never touching the robot.
    assert np.max(np.abs(ys - 1.5)) >= 0.45
    assert np.max(np.abs(ys - 1.5)) <= 0.6 + 1e-9
    # It kept 0.1 m from the robot's footprint (a collision monitor's stop zone is 1 cm).
    assert np.min(distances) >= 0.25 + ROBOT.footprint_radius_m + 0.1 - 1e-9
    assert sim.collision_count == 0
    # It only left the path near the robot.
    assert np.all(np.abs(ys[xs > 3.5] - 1.5) < 1e-9)


def test_a_walking_person_waits_where_there_is_no_room_then_turns_back(tmp_path):
    """In a 0.9 m corridor nobody passes the robot: the person waits 3 s, then turns back."""
    world = walk_world(tmp_path, 0.9)
    sim = Simulation(world, ROBOT, quiet_config())
    sim.physics.teleport(2.0, 0.45, 0.0)
    run_for(sim, 4.0)   # it arrives after about 2.4 s and waits
    x, y, _ = sim.moving_circles()[0]
    # Stops at the robot (x 2.0) + footprint 0.2 + gap 0.15 + radius 0.25 = 2.6, give or
    # take a step; no room to step aside between the walls.
    assert x == pytest.approx(2.0 + ROBOT.footprint_radius_m + 0.15 + 0.25, abs=0.01)
    assert y == pytest.approx(0.45, abs=0.01)
    assert sim.collision_count == 0
    run_for(sim, 2.5)   # after 3 s of waiting it turns back toward x = 4.5
    assert sim.moving_circles()[0][0] > 2.6 + 0.5
    # The person's way back (loop: false walks back) leads away from the robot: it goes.
    other = Simulation(world, ROBOT, quiet_config())
    other.physics.teleport(5.5, 0.45, 0.0)   # behind the person's start
    run_for(other, 3.0)
    assert other.moving_circles()[0][0] == pytest.approx(4.5 - 0.8 * 3.0, abs=0.01)
