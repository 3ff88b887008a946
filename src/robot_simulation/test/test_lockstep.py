"""Unit tests of the simulator's lockstep gate (robot_simulation.lockstep), no ROS."""

import pytest
from robot_simulation.lockstep import BOARD, Lockstep, LockstepConfig, LockstepError


def started(timeout_s=2.0, give_up_s=10.0) -> Lockstep:
    """Return a gate whose board has answered once (the stack is up), at wall 0."""
    gate = Lockstep(LockstepConfig(timeout_s=timeout_s, give_up_s=give_up_s))
    gate.published(0.0, wall_s=0.0)
    gate.board_command(wall_s=0.0)
    gate.events()
    return gate


def test_before_the_board_answers_time_is_not_locked():
    gate = Lockstep()
    gate.published(0.02, wall_s=0.0)
    assert gate.waiting_for(100.0) == []
    assert gate.free_running


def test_each_clock_waits_for_a_board_command_after_it():
    gate = started()
    assert not gate.free_running
    gate.published(0.02, wall_s=1.0)
    assert gate.waiting_for(1.001) == [BOARD]
    gate.board_command(wall_s=1.002)
    assert gate.waiting_for(1.003) == []
    # A command that came before the next /clock does not answer it.
    gate.published(0.04, wall_s=1.004)
    assert gate.waiting_for(1.005) == [BOARD]


def test_participants_answer_the_clock_they_took():
    gate = started()
    gate.ack('navigation_container', 0.0, wall_s=0.0)
    gate.published(0.02, wall_s=1.0)
    gate.board_command(wall_s=1.001)
    assert gate.waiting_for(1.001) == ['navigation_container']
    gate.ack('navigation_container', 0.02, wall_s=1.002)
    assert gate.waiting_for(1.002) == []
    # An old ack arriving late does not move the participant back.
    gate.ack('navigation_container', 0.0, wall_s=1.003)
    assert gate.last_answer_sim_s('navigation_container') == pytest.approx(0.02)
    assert gate.participants == ['navigation_container']


def test_a_silent_part_is_gone_after_the_timeout_and_takes_part_again_when_it_answers():
    gate = started(timeout_s=2.0)
    gate.ack('amcl', 0.0, wall_s=0.0)
    gate.published(0.02, wall_s=1.0)
    gate.board_command(wall_s=1.0)
    assert gate.waiting_for(2.9) == ['amcl']
    assert gate.waiting_for(3.0) == []          # 2 s after the /clock: gone
    assert gate.free_running
    assert any('amcl has not answered /clock 0.02 s for 2.0 s' in e for e in gate.events())
    gate.published(0.04, wall_s=3.1)
    gate.board_command(wall_s=3.1)
    assert gate.waiting_for(3.2) == []          # gone: not awaited
    gate.ack('amcl', 0.04, wall_s=3.3)
    assert gate.events() == ['lockstep: amcl answers again']
    assert not gate.free_running
    gate.published(0.06, wall_s=3.4)
    gate.board_command(wall_s=3.4)
    assert gate.waiting_for(3.5) == ['amcl']


def test_a_busy_part_that_is_alive_is_waited_for_up_to_give_up():
    gate = started(timeout_s=2.0, give_up_s=10.0)
    gate.ack('slam_toolbox', 0.0, wall_s=0.0)
    gate.published(0.02, wall_s=1.0)
    gate.board_command(wall_s=1.0)
    for wall_s in (2.0, 3.0, 4.0, 5.0):        # busy in a long callback, alive each second
        gate.alive('slam_toolbox', wall_s)
    assert gate.waiting_for(5.5) == ['slam_toolbox']     # 4.5 s > timeout_s, but alive
    assert not gate.free_running
    assert gate.waiting_for(7.0) == []                   # 2 s without a sign: gone
    assert any('slam_toolbox has not answered /clock 0.02 s for 6.0 s' in event
               for event in gate.events())


def test_a_part_alive_but_busy_past_give_up_is_gone():
    gate = started(timeout_s=2.0, give_up_s=10.0)
    gate.ack('slam_toolbox', 0.0, wall_s=0.0)
    gate.published(0.02, wall_s=1.0)
    gate.board_command(wall_s=1.0)
    for second in range(2, 12):
        gate.alive('slam_toolbox', float(second))
    assert gate.waiting_for(10.9) == ['slam_toolbox']
    assert gate.waiting_for(11.0) == []
    assert any('slam_toolbox has been busy with /clock 0.02 s for 10.0 s' in event
               for event in gate.events())


def test_alive_before_taking_part_is_ignored():
    gate = started()
    gate.alive('amcl', wall_s=0.5)
    assert gate.participants == []


def test_a_board_silent_past_give_up_ends_the_run_naming_it():
    gate = started(timeout_s=1.0, give_up_s=5.0)
    gate.published(0.02, wall_s=0.5)
    assert gate.waiting_for(1.4) == [BOARD]
    assert gate.waiting_for(1.5) == []          # gone after 1 s
    assert gate.free_running
    assert gate.waiting_for(4.9) == []
    with pytest.raises(LockstepError, match='hardware_interface.*has not answered for 5 s'):
        gate.waiting_for(5.0)                   # 5 s since its last command (wall 0)


def test_a_board_that_answers_again_is_locked_again():
    gate = started(timeout_s=1.0)
    gate.published(0.02, wall_s=0.0)
    gate.waiting_for(1.0)
    assert gate.free_running
    gate.board_command(wall_s=1.5)
    assert 'answers again' in gate.events()[-1]
    gate.published(0.04, wall_s=1.6)
    assert gate.waiting_for(1.7) == [BOARD]


@pytest.mark.parametrize('timeout_s, give_up_s', [
    (0.0, 1.0), (-1.0, 1.0), (float('nan'), 1.0), (2.0, 1.0), (1.0, float('inf'))])
def test_bad_limits_are_refused(timeout_s, give_up_s):
    with pytest.raises(ValueError, match='lockstep'):
        LockstepConfig(timeout_s=timeout_s, give_up_s=give_up_s)


def test_a_part_said_down_is_not_waited_for_at_once_and_takes_part_again_when_it_answers():
    gate = started(timeout_s=2.0)
    gate.ack('twist_mux', 0.0, wall_s=0.0)
    gate.published(0.02, wall_s=1.0)
    gate.board_command(wall_s=1.0)
    assert gate.waiting_for(1.001) == ['twist_mux']
    gate.events()
    gate.down('twist_mux', 'killed')             # long before the 2 s timeout
    assert gate.waiting_for(1.002) == []
    assert gate.free_running
    assert gate.events() == [
        'lockstep: twist_mux is down (killed): going on without it, at real time at most',
        f'lockstep: not waiting for {BOARD} while twist_mux is down']
    gate.down('twist_mux', 'killed')             # already gone: nothing new
    gate.down('never_heard', 'killed')           # not a participant: ignored
    assert gate.events() == [] and gate.participants == ['twist_mux']
    # The respawned process (same name) takes the next /clock: locked again.
    gate.published(0.04, wall_s=1.1)
    gate.board_command(wall_s=1.1)
    gate.ack('twist_mux', 0.04, wall_s=1.2)
    assert gate.events() == ['lockstep: twist_mux answers again']
    assert not gate.free_running


def test_while_a_part_said_down_is_gone_the_board_is_not_waited_for():
    """
    A killed velocity_controller or hardware_interface: nothing may command the board.

    hardware_interface's keep-alive runs on simulated time, so waiting for the board
    would hold time until the lockstep timeout (10 s of wall time) at such a kill; a
    late command of the killed node must not bring that wait back (the test saw it).
    """
    gate = started(timeout_s=10.0, give_up_s=30.0)
    gate.ack('velocity_controller', 0.0, wall_s=0.0)
    gate.published(0.02, wall_s=1.0)
    assert gate.waiting_for(1.001) == [BOARD, 'velocity_controller']
    gate.events()
    gate.down('velocity_controller', 'killed')   # long before the 10 s timeout
    assert gate.waiting_for(1.002) == []
    assert gate.free_running
    assert gate.events() == [
        'lockstep: velocity_controller is down (killed): going on without it, at real time '
        'at most',
        f'lockstep: not waiting for {BOARD} while velocity_controller is down']
    # A command that was on its way: the next /clock still does not wait for the board.
    gate.board_command(wall_s=1.1)
    gate.published(0.04, wall_s=1.2)
    assert gate.waiting_for(1.201) == []
    # Down and silent for give_up_s: the stack is gone for good.
    with pytest.raises(LockstepError, match='has not answered for 30 s'):
        gate.waiting_for(31.2)


def test_the_board_is_waited_for_again_once_the_part_said_down_answers():
    gate = started(timeout_s=10.0)
    gate.ack('hardware_interface', 0.0, wall_s=0.0)
    gate.published(0.02, wall_s=1.0)
    gate.down('hardware_interface', 'killed')
    assert gate.waiting_for(1.001) == []
    gate.published(0.04, wall_s=2.0)
    gate.board_command(wall_s=2.1)               # the respawned hardware_interface
    gate.ack('hardware_interface', 0.04, wall_s=2.1)
    assert not gate.free_running
    gate.published(0.06, wall_s=2.2)
    assert gate.waiting_for(2.201) == [BOARD, 'hardware_interface']
    # Before the board ever answered (the stack starting), nothing is said of it.
    fresh = Lockstep(LockstepConfig(timeout_s=10.0))
    fresh.ack('hardware_interface', 0.0, wall_s=0.0)
    fresh.down('hardware_interface', 'killed')
    assert fresh.events() == [
        'lockstep: hardware_interface takes part',
        'lockstep: hardware_interface is down (killed): going on without it, at real time '
        'at most']
