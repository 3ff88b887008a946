"""Tests of the simulation core with faults injected (robot_simulation.simulator + faults)."""

import math
from pathlib import Path
import textwrap

from mecanum_control.board_sim import PtyPort, SerialLine
from mecanum_control.esp32_protocol import FaultFlags
from mecanum_control.robot_config import default_config_path, load_robot_config
import numpy as np
import pytest
from robot_simulation.faults import FaultError, parse_fault
from robot_simulation.sensors import ImuConfig, LidarConfig, STANDARD_GRAVITY_M_S2
from robot_simulation.simulator import Simulation, SimulatorConfig
from robot_simulation.world import find_world, load_world

ROBOT = load_robot_config(default_config_path())
G = STANDARD_GRAVITY_M_S2


def box_world(tmp_path: Path):
    """Return a 4 m x 3 m empty room, robot at (1, 1.5) facing +x, test zone x < 2."""
    path = tmp_path / 'box.yaml'
    path.write_text(textwrap.dedent("""
        world:
          name: box
          bounds_m: [0.0, 0.0, 4.0, 3.0]
          test_zone: [[0.1, 0.1], [2.0, 0.1], [2.0, 2.9], [0.1, 2.9]]
          robot_start: {x_m: 1.0, y_m: 1.5, yaw_deg: 0.0}
        """))
    return load_world(path)


def quiet_config() -> SimulatorConfig:
    """Sensors without noise or bias, for hand-worked numbers."""
    return SimulatorConfig(
        lidar=LidarConfig(noise_stddev_m=0.0),
        imu=ImuConfig(gyro_noise_stddev_rad_s=0.0, gyro_bias_stddev_rad_s=0.0,
                      accel_noise_stddev_m_s2=0.0, accel_bias_stddev_m_s2=0.0))


def inject(sim: Simulation, **raw) -> None:
    """Schedule one fault (parse_fault's mapping, onset absolute)."""
    assert sim.add_fault(parse_fault(raw)) is None


def steps(sim: Simulation, seconds: float, duties=None, record=None) -> None:
    """Step for seconds, commanding duties every 0.1 s; record(sim) after each step."""
    for step in range(int(round(seconds / sim.dt_s))):
        if duties is not None and step % 20 == 0:
            sim.board.command(duties, 250, step)
        sim.step()
        if record is not None:
            record(sim)


def test_faults_change_nothing_unless_they_act_and_then_only_their_part():
    """
    A fault changes nothing before its onset, and then only what it acts on.

    Three seeded noisy runs in the apartment: no fault; a fault due after the run; the
    lidar blinded and its stamps skewed for 0.2 s. The first two agree to the bit in
    everything; the third only in what the lidar does not touch, and in its scans
    after the fault.
    """
    world = load_world(find_world('apartment'))

    def run(*faults):
        sim = Simulation(world, ROBOT, SimulatorConfig(seed=3))
        for raw in faults:
            inject(sim, **raw)
        log = {'poses': [], 'counts': [], 'imu': [], 'scans': [], 'stamp_offsets': []}

        def record(sim):
            state = sim.physics.state
            log['poses'].append((state.x, state.y, state.yaw, state.vx, state.vy, state.wz))
            log['counts'].append(sim.board.hw.read_counts())
            if sim.steps % 2 == 0:
                log['imu'].append(sim.board.hw.read_imu())
            if sim.steps % 20 == 0:
                ranges = sim.lidar_output()
                log['scans'].append(None if ranges is None else ranges.tolist())
                log['stamp_offsets'].append(sim.faults.effects.scan_stamp_offset_s)
        steps(sim, 1.0, [0.4, 0.2, 0.4, 0.2], record)
        return log, sim
    plain, plain_sim = run()
    later, _ = run({'kind': 'imu_silent', 'onset_s': 50.0})
    assert later == plain
    assert plain_sim.fault_changes == []
    blind, blind_sim = run({'kind': 'lidar_blinded', 'onset_s': 0.25, 'duration_s': 0.2},
                           {'kind': 'scan_stamp_skew', 'onset_s': 0.25, 'duration_s': 0.2,
                            'offset_s': 0.3})
    for key in ('poses', 'counts', 'imu'):
        assert blind[key] == plain[key]
    # Scans at 0.1 s .. 1.0 s: 0.3 and 0.4 s blinded (and stamped 0.3 s late).
    assert blind['scans'][:2] == plain['scans'][:2]
    assert blind['scans'][2] == blind['scans'][3] == [math.inf] * 360
    assert blind['scans'][4:] == plain['scans'][4:]
    assert blind['stamp_offsets'] == [0.0, 0.0, 0.3, 0.3] + [0.0] * 6
    assert plain['stamp_offsets'] == [0.0] * 10
    assert [len(change.started) for change in blind_sim.fault_changes] == [2, 0]
    assert [len(change.ended) for change in blind_sim.fault_changes] == [0, 2]


def test_lidar_frozen_repeats_the_onset_scan_and_silent_sends_none(tmp_path):
    sim = Simulation(box_world(tmp_path), ROBOT, quiet_config())
    inject(sim, kind='lidar_frozen', onset_s=0.1, duration_s=0.5)
    inject(sim, kind='lidar_silent', onset_s=0.7, duration_s=0.1)
    steps(sim, 0.1, [0.3] * 4)
    frozen = sim.lidar_output()
    assert np.array_equal(frozen, sim.scan())
    steps(sim, 0.3, [0.3] * 4)   # the robot drives on toward the east wall
    assert sim.physics.state.x > 1.05
    assert np.array_equal(sim.lidar_output(), frozen)
    assert not np.array_equal(sim.scan(), frozen)
    steps(sim, 0.2, [0.3] * 4)   # 0.6 s: thawed
    assert np.array_equal(sim.lidar_output(), sim.scan())
    steps(sim, 0.1, [0.3] * 4)   # 0.7 s: silent
    assert sim.lidar_output() is None
    steps(sim, 0.1, [0.3] * 4)
    assert sim.lidar_output() is not None


def test_encoder_stuck_holds_the_count_and_it_counts_on_behind(tmp_path):
    """
    FL stuck 0.2..0.5 s while all four wheels turn: the board reads FL's count of 0.2 s.

    After the fault FL counts on from there: it stays behind the wheel by the pulses it
    missed during the fault, the others read their wheels.
    """
    sim = Simulation(box_world(tmp_path), ROBOT, quiet_config())
    inject(sim, kind='encoder_stuck', onset_s=0.2, duration_s=0.3, wheel='FL')
    steps(sim, 0.2, [0.3] * 4)
    held = sim.board.ticks[0]
    assert held > 0
    steps(sim, 0.295, [0.3] * 4)   # 0.495 s
    true = sim.board.ticks
    reading = sim.board.hw.read_counts()
    assert reading == (held,) + true[1:]
    assert sim.board.core.counts[0] == held   # what the firmware sampled and reports
    assert true[0] > held + 20
    steps(sim, 0.005, [0.3] * 4)   # 0.5 s: the fault ends
    missed = sim.board.ticks[0] - held
    steps(sim, 0.2, [0.3] * 4)
    true = sim.board.ticks
    assert sim.board.hw.read_counts() == (true[0] - missed,) + true[1:]
    assert sim.board.hw.read_counts()[0] > held
    lines = [text for change in sim.fault_changes for _, text in change.log_lines()]
    assert lines == ['fault encoder_stuck (wheel FL) on at 0.2 s for 0.3 s',
                     'fault encoder_stuck (wheel FL) off at 0.5 s']


def test_imu_bias_then_imu_silent_on_the_board(tmp_path):
    """At rest a quiet IMU reads (0, 0, g, 0, 0, 0); the bias adds (ax, ay, gz)."""
    sim = Simulation(box_world(tmp_path), ROBOT, quiet_config())
    inject(sim, kind='imu_bias', onset_s=0.0, duration_s=0.1, gyro_z_rad_s=0.1,
           accel_x_m_s2=-0.2, accel_y_m_s2=0.3)
    inject(sim, kind='imu_silent', onset_s=0.1, duration_s=0.1)
    steps(sim, 0.005)
    assert sim.board.hw.read_imu() == pytest.approx((-0.2, 0.3, G, 0.0, 0.0, 0.1))
    steps(sim, 0.1)
    assert sim.board.hw.read_imu() is None
    # The firmware takes a silent IMU for a failed one: IMU_FAULT, latched.
    sim.board.core.poll(report=True)
    assert sim.board.faults & FaultFlags.IMU_FAULT
    steps(sim, 0.1)
    assert sim.board.hw.read_imu() == pytest.approx((0.0, 0.0, G, 0.0, 0.0, 0.0))


def test_wheel_slip_sets_the_traction_of_one_wheel_while_it_acts(tmp_path):
    sim = Simulation(box_world(tmp_path), ROBOT, quiet_config())
    inject(sim, kind='wheel_slip', onset_s=0.05, duration_s=0.1, wheel='RL',
           traction_factor=0.0)
    steps(sim, 0.05)
    assert sim.physics.traction_factors == (1.0, 1.0, 0.0, 1.0)
    steps(sim, 0.1)
    assert sim.physics.traction_factors == (1.0, 1.0, 1.0, 1.0)


def test_serial_faults_reach_the_boards_line(tmp_path):
    sim = Simulation(box_world(tmp_path), ROBOT, quiet_config())
    line = SerialLine(PtyPort(tmp_path / 'tty'), seed=2)
    sim.board.attach(line)
    try:
        inject(sim, kind='serial_drop_bytes', onset_s=0.0, duration_s=0.05, rate=0.3)
        inject(sim, kind='serial_bit_flips', onset_s=0.0, duration_s=0.05, rate=0.01)
        inject(sim, kind='serial_latency', onset_s=0.0, duration_s=0.05, latency_s=0.02)
        steps(sim, 0.005)
        assert (line.byte_drop_rate, line.bit_flip_rate, line.latency_s) == (
            pytest.approx(0.3), pytest.approx(0.01), 0.02)
        assert line.faulty
        steps(sim, 0.05)
        assert (line.byte_drop_rate, line.bit_flip_rate, line.latency_s) == (0.0, 0.0, 0.0)
        steps(sim, 0.02)   # what was on its way has arrived
        assert not line.faulty
    finally:
        line.port.unplug()


def test_kidnap_moves_the_true_robot_keeping_its_motion(tmp_path):
    """Kidnap by (1.5, -0.5, 90 deg) at 0.5 s; the zone exit it causes is not the robot's."""
    sim = Simulation(box_world(tmp_path), ROBOT, quiet_config())
    inject(sim, kind='kidnap', onset_s=0.5, dx_m=1.5, dy_m=-0.5, dyaw_rad=math.pi / 2)
    steps(sim, 0.495, [0.3] * 4)
    before = sim.physics.state
    steps(sim, 0.005, [0.3] * 4)
    after = sim.physics.state
    # One physics step before the jump: compare with its own small motion allowed.
    assert after.x == pytest.approx(before.x + 1.5, abs=0.005)
    assert after.y == pytest.approx(before.y - 0.5, abs=1e-6)
    assert after.yaw == pytest.approx(before.yaw + math.pi / 2, abs=1e-6)
    assert after.vx == pytest.approx(before.vx, rel=0.05) and after.vx > 0.05
    assert sim.left_test_zone_count == 0 and not sim.in_test_zone
    (change,) = sim.fault_changes
    (fault, refused, text), = change.outcomes
    assert refused is None and text.startswith('the robot moved from (')
    assert change.log_lines()[0][0] == 'info'


def test_kidnap_onto_a_wall_or_a_person_is_refused_and_nothing_moves(tmp_path):
    """The east wall is at x = 4: a kidnap to x 3.9 would overlap it (footprint 0.2 m)."""
    sim = Simulation(box_world(tmp_path), ROBOT, quiet_config())
    inject(sim, kind='kidnap', onset_s=0.0, dx_m=2.9)
    steps(sim, 0.005)
    assert (sim.physics.state.x, sim.physics.state.y) == (1.0, 1.5)
    (fault, refused, text), = sim.fault_changes[0].outcomes
    assert refused == 'a wall or furniture (or the world edge)'
    assert 'would land on a wall or furniture (or the world edge) at (3.900, 1.500' in text
    assert sim.fault_changes[0].log_lines()[0][0] == 'error'
    # A person walks from (4.5, 1.5) toward x 0.5; the robot stands at (5.5, 1.5).
    path = tmp_path / 'walk.yaml'
    path.write_text(textwrap.dedent("""
        world:
          name: walk
          bounds_m: [0.0, 0.0, 6.0, 3.0]
          moving_obstacles:
          - {name: person, radius_m: 0.25, speed_m_s: 0.8,
             path: [[4.5, 1.5], [0.5, 1.5]], loop: false}
          robot_start: {x_m: 5.5, y_m: 1.5, yaw_deg: 0.0}
        """))
    sim = Simulation(load_world(path), ROBOT, quiet_config())
    inject(sim, kind='kidnap', onset_s=0.0, dx_m=-1.0)
    steps(sim, 0.005)
    assert sim.physics.state.x == 5.5
    assert sim.fault_changes[0].outcomes[0][1] == 'a person'


def test_runner_faults_are_refused_by_the_simulation(tmp_path):
    sim = Simulation(box_world(tmp_path), ROBOT, quiet_config())
    with pytest.raises(FaultError, match='scenario runner'):
        sim.add_fault(parse_fault({'kind': 'node_frozen', 'node': 'amcl'}))
