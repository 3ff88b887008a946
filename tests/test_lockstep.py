"""
Integration: lockstep. Simulated time waits for the stack, and a silent stack is named.

1. The simulator alone, in lockstep at 'max', with the test as the board's host on the
   real pseudo-terminal (real protocol frames): one MOTOR_EFFORTS engages the lockstep;
   then the host falls silent. Simulated time must stop right there (not one /clock past
   the unanswered one), the simulator must say after lockstep_timeout_s that the board
   has not answered, run on at real time at most, and after lockstep_give_up_s end with
   exit code 1 and a FATAL line naming hardware_interface.
2. The whole simulated robot (robot_simulation simulation.launch.yaml, every node its
   own process) in lockstep at 'max': freezing one process of the stack (SIGSTOP
   velocity_controller) stops simulated time at once; the simulator names the process
   after the timeout; resumed (SIGCONT), it takes part again.
3. A test node that answers /clock (TestNode.answer_clock, as test_slam's route driver
   does) holds simulated time the same way while it holds its answers.
"""

import os
from pathlib import Path
import signal
import sys
import time

from mecanum_control import esp32_protocol as proto
import pytest
from rosgraph_msgs.msg import Clock
import serial
from tests.conftest import interrupt_group, OutputProcess

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[1]
PERIOD_S = 0.02    # the simulator's clock_period_s


def clock_s(msg: Clock) -> float:
    """Return a /clock message's time in seconds."""
    return msg.clock.sec + msg.clock.nanosec * 1e-9


class Process(OutputProcess):
    """A process started in the repository, stopped as Ctrl-C would (then killed)."""

    def __init__(self, command, env):
        super().__init__(command, env, cwd=str(REPO))

    def stop(self):
        interrupt_group(self.process)


def simulator_alone(ros_env, port, timeout_s: float, give_up_s: float) -> Process:
    """Start the simulator alone in lockstep at max, its board on port (a pty)."""
    return Process([sys.executable, '-m', 'robot_simulation.simulator_node', '--ros-args',
                    '-p', 'world:=apartment', '-p', f'board_port:={port}',
                    '-p', 'lockstep:=true', '-p', 'real_time_factor:=0.0',
                    '-p', f'lockstep_timeout_s:={timeout_s}',
                    '-p', f'lockstep_give_up_s:={give_up_s}'], ros_env)


def test_the_simulator_waits_for_the_board_and_names_it_when_it_stays_silent(
        ros_env, test_node, tmp_path):
    port = tmp_path / 'ttySIM'
    sim = simulator_alone(ros_env, port, timeout_s=1.0, give_up_s=4.0)
    try:
        clock = test_node.record(Clock, '/clock')
        # Before the board answers, time runs (at real time at most): the stack starts.
        clock.wait_for(lambda m: clock_s(m) > 0.2, timeout=60)
        host = serial.Serial(str(port), 115200, timeout=0.1)
        try:
            sent_at_s = clock_s(clock.latest())
            host.write(b'\x00' + proto.encode_frame(
                proto.MotorEfforts((0.0, 0.0, 0.0, 0.0), 200), 0))
            sim.wait_for_line_at(r'lockstep: the board .* answers: simulated time now waits',
                                 timeout=30)
            silent_at, match = sim.wait_for_line_at(
                r'lockstep: the board \(MOTOR_EFFORTS from hardware_interface\) has not '
                r'answered /clock (\d+\.\d+) s for 1\.\d s', timeout=30)
            stalled_s = float(match.group(1))
            # Time stopped at the first /clock after the one command: not one more /clock.
            assert stalled_s - sent_at_s < 0.1, (sent_at_s, stalled_s)
            late = [clock_s(msg) for when, msg in clock.messages
                    if when < silent_at - 0.05 and clock_s(msg) > stalled_s + 1e-6]
            assert not late, f'/clock ran past {stalled_s} s while the board owed an answer'
            # Gone: time runs on (at real time at most) until the give-up.
            clock.wait_for(lambda m: clock_s(m) > stalled_s + 0.5, timeout=10)
            sim.wait_for_line_at(r'\[FATAL\].*lockstep: the board \(MOTOR_EFFORTS from '
                                 r'hardware_interface\) has not answered for 4 s', timeout=30)
            assert sim.process.wait(timeout=20) == 1
            assert 'Traceback' not in sim.output()
        finally:
            host.close()
    finally:
        sim.stop()


def test_a_test_node_that_answers_the_clock_holds_simulated_time(ros_env, test_node,
                                                                 tmp_path):
    """
    TestNode.answer_clock: a test that drives the robot is waited for (test_slam's route).

    CI at 870cc44 (loaded): test_slam's route driver, then outside the lockstep, fell
    behind simulated time at max speed, the robot overshot a corner into the collision
    monitor's stop zone and the route never ended.
    """
    sim = simulator_alone(ros_env, tmp_path / 'ttySIM', timeout_s=2.0, give_up_s=60.0)
    try:
        clock = test_node.record(Clock, '/clock')
        answers = test_node.answer_clock('route_driver')
        sim.wait_for_line_at(r'lockstep: route_driver takes part', timeout=60)
        answers.hold()
        held_at = time.monotonic()
        silent_at, match = sim.wait_for_line_at(
            r'lockstep: route_driver has not answered /clock (\d+\.\d+) s for', timeout=30)
        stalled_s = float(match.group(1))
        late = [clock_s(msg) for when, msg in clock.messages
                if held_at + 0.2 <= when < silent_at - 0.05 and clock_s(msg) > stalled_s + 1e-6]
        assert not late, f'/clock ran past {stalled_s} s while the test owed an answer'
        answers.release()
        sim.wait_for_line_at(r'lockstep: route_driver answers again', timeout=30)
        clock.wait_for(lambda m: clock_s(m) > stalled_s + 0.5, timeout=30)
    finally:
        sim.stop()


def test_a_frozen_process_of_the_stack_stops_simulated_time(start_system, test_node, tmp_path):
    system = start_system('robot_simulation', 'simulation.launch.yaml', 'world:=apartment',
                          f'board_port:={tmp_path / "ttySIM"}', 'lockstep:=true',
                          'real_time_factor:=0.0', f'estop_latch_file:={tmp_path / "estop"}')
    system.wait_for_line(r'lockstep: the board .* answers: simulated time now waits', 90)
    system.wait_for_line(r'lockstep: velocity_controller takes part', 30)
    clock = test_node.record(Clock, '/clock')
    clock.wait_for(lambda m: True, timeout=30)
    pid = system.node_pid('velocity_controller')
    os.kill(pid, signal.SIGSTOP)
    frozen_at = time.monotonic()
    try:
        match = system.wait_for_line(
            r'lockstep: velocity_controller has not answered /clock (\d+\.\d+) s for', 30)
        stalled_s = float(match.group(1))
        # Every /clock received from the freeze until the simulator gave up on the process
        # is at most one period past the first one it did not answer.
        gave_up = time.monotonic()
        print(f'frozen at wall {frozen_at:.2f} s, stalled at /clock {stalled_s:.2f} s, '
              f'the simulator went on without it at wall {gave_up:.2f} s')
        in_stall = [clock_s(msg) for when, msg in clock.messages
                    if frozen_at + 0.2 <= when <= gave_up - 1.0]
        assert in_stall == [] or max(in_stall) <= stalled_s + 1e-6, (stalled_s, in_stall[-5:])
    finally:
        os.kill(pid, signal.SIGCONT)
    system.wait_for_line(r'lockstep: velocity_controller answers again', 30)
    # Locked again: simulated time runs on.
    now_s = clock_s(clock.latest())
    clock.wait_for(lambda m: clock_s(m) > now_s + 1.0, timeout=30)
    assert system.stop() == 0


def test_a_killed_process_respawned_under_its_name_takes_part_again_at_once(
        start_system, test_node, tmp_path):
    system = start_system('robot_simulation', 'simulation.launch.yaml', 'world:=apartment',
                          f'board_port:={tmp_path / "ttySIM"}', 'lockstep:=true',
                          'real_time_factor:=0.0', f'estop_latch_file:={tmp_path / "estop"}')
    system.wait_for_line(r'lockstep: the board .* answers: simulated time now waits', 90)
    system.wait_for_line(r'lockstep: robot_controller takes part', 30)
    clock = test_node.record(Clock, '/clock')
    clock.wait_for(lambda m: True, timeout=30)
    os.kill(system.node_pid('robot_controller'), signal.SIGKILL)
    killed_at_s = clock_s(clock.latest())
    system.wait_for_line(r'restarted robot_controller', 30)
    # Within the give-up (60 s), well past what a restart takes: time runs on in lockstep.
    clock.wait_for(lambda m: clock_s(m) > killed_at_s + 2.0, timeout=45)
    output = system.output()
    assert 'busy with /clock' not in output, output[-3000:]
    assert system.stop() == 0
