"""Unit tests of the expected reactions to faults and their judging (no ROS)."""

from pathlib import Path

from mecanum_bringup.fault_reactions import (
    CONTINUES, judge_reaction, reaction_for, REACTIONS, SAFE)
from mecanum_bringup.scenario_judge import judge
from mecanum_bringup.scenario_loader import load_scenario
from mecanum_bringup.scenario_model import RunRecord, StepResult
import numpy as np
import pytest
from robot_simulation.faults import FAULT_KINDS


def track(speeds, dt=0.02, t0=0.0, turn_rate=0.0):
    """Return a track along x (t, x, y, yaw rows) with the speed of each interval (m/s)."""
    rows = [(t0, 0.0, 0.0, 0.0)]
    for speed in speeds:
        t, x, _, yaw = rows[-1]
        rows.append((t + dt, x + speed * dt, 0.0, yaw + turn_rate * dt))
    return np.array(rows)


def blinded(began=1.0, ended=3.0):
    return {'kind': 'lidar_blinded', 'onset_s': began, 'duration_s': ended - began,
            'began_s': began, 'ended_s': ended}


LIVE = [(0.0, 'twist_mux', 'navigation')]


def test_every_fault_kind_has_an_expected_reaction():
    for kind in FAULT_KINDS:
        reaction = reaction_for({'kind': kind, 'node': 'some_node'})
        assert reaction.mission in (CONTINUES, SAFE)
        assert reaction.does
    assert reaction_for({'kind': 'node_killed', 'node': 'twist_mux'}).stop_within_s == \
        pytest.approx(0.25 + 0.65 + 0.1)
    assert reaction_for({'kind': 'node_killed', 'node': 'planner'}) is \
        REACTIONS['node_killed:*']


def test_a_stop_reaction_wants_rest_from_its_delay_to_the_faults_end():
    # 0.5 m/s for 1.5 s (to t = 1.5), then at rest to t = 4: blinded 1 .. 3 s, stop
    # within 1 s: the window 2 .. 3 s is at rest.
    truth = track([0.5] * 75 + [0.0] * 125)
    states = LIVE + [(1.0, 'collision_monitor', 'STOP invalid source: scan blinded')]
    result = judge_reaction(blinded(), truth, states, goals_reached=True)
    assert result.passed, result.detail
    assert result.detail == ('lidar_blinded: at rest from +1 s to +2.0 s, collision_monitor '
                             'said "STOP invalid source: scan blinded", goals reached')
    # Still moving at 2.1 s (0.5 m/s until t = 2.2): the first interval in the window
    # that moves is the one ending at 2.02 s.
    late = track([0.5] * 110 + [0.0] * 90)
    result = judge_reaction(blinded(), late, states, goals_reached=True)
    assert not result.passed
    assert 'moving at 0.50 m/s at t=2.02 s, 1.02 s after it began' in result.detail


def test_turning_on_the_spot_passes_only_where_allowed():
    spinning = track([0.0] * 200, turn_rate=0.3)
    states = LIVE + [(1.2, 'zone_guard', 'STOP localisation unhealthy: position sigma 0.4 m')]
    diverged = {'kind': 'amcl_diverged', 'onset_s': 1.0, 'duration_s': 0.0, 'began_s': 1.0,
                'ended_s': 1.0, 'applied': True}
    assert judge_reaction(diverged, spinning, states, goals_reached=False).passed
    estop = {'kind': 'estop', 'onset_s': 1.0, 'duration_s': 2.0, 'began_s': 1.0,
             'ended_s': 3.0}
    result = judge_reaction(estop, spinning, LIVE + [(1.0, 'twist_mux', 'locked by e_stop')],
                            goals_reached=False)
    assert not result.passed and 'moving at 0.30 rad/s' in result.detail


def test_the_reason_is_wanted_only_while_a_source_was_live():
    truth = track([0.0] * 200)
    wrong = LIVE + [(1.0, 'collision_monitor', 'STOP PolygonStop')]
    result = judge_reaction(blinded(), truth, wrong, goals_reached=None)
    assert not result.passed
    assert 'no stage said why (expected collision_monitor "scan blinded")' in result.detail
    # Nothing was commanded (twist_mux none throughout): nothing to stop, nothing to say.
    idle = [(0.0, 'twist_mux', 'none')]
    assert judge_reaction(blinded(), truth, idle, goals_reached=None).passed
    # A source that became live during the fault wants the reason again.
    waking = idle + [(2.5, 'twist_mux', 'teleop_keyboard')]
    assert not judge_reaction(blinded(), truth, waking, goals_reached=None).passed
    # Said within SAYS_GRACE_S after the end still counts; later does not.
    for said_at, passed in ((3.4, True), (3.6, False)):
        states = LIVE + [(said_at, 'collision_monitor', 'STOP invalid source: scan blinded')]
        assert judge_reaction(blinded(), truth, states, None).passed is passed


def test_ridden_out_faults_want_the_goals_reached():
    imu = {'kind': 'imu_silent', 'onset_s': 1.0, 'duration_s': 2.0, 'began_s': 1.0,
           'ended_s': 3.0}
    moving = track([0.4] * 200)
    assert judge_reaction(imu, moving, LIVE, goals_reached=True).passed
    assert judge_reaction(imu, moving, LIVE, goals_reached=None).passed
    result = judge_reaction(imu, moving, LIVE, goals_reached=False)
    assert not result.passed and 'a goal was not reached' in result.detail


def test_a_fault_that_never_acted_fails():
    never = dict(blinded(), began_s=None, ended_s=None, onset_s=30.0)
    result = judge_reaction(never, track([0.0] * 10), LIVE, None)
    assert not result.passed
    assert result.detail == 'lidar_blinded: never acted within the run (onset 30.0 s)'
    refused = {'kind': 'kidnap', 'onset_s': 1.0, 'duration_s': 0.0, 'began_s': 1.0,
               'ended_s': 1.0, 'applied': False, 'outcome': 'refused: in a wall'}
    assert judge_reaction(refused, track([0.0] * 10), LIVE, None).detail == \
        'kidnap: not applied: refused: in a wall'


def test_a_kill_wants_the_robot_at_rest_once_within_the_delay():
    # twist_mux killed at 1 s: at rest in the interval ending at 1.92 s (0.92 s after,
    # within the 1 s), then the respawned one drives it on.
    killed = {'kind': 'node_killed', 'node': 'twist_mux', 'onset_s': 1.0, 'duration_s': 0.0,
              'began_s': 1.0, 'ended_s': 1.0}
    truth = track([0.5] * 95 + [0.0] * 2 + [0.5] * 103)
    result = judge_reaction(killed, truth, LIVE, goals_reached=True)
    assert result.passed, result.detail
    assert result.detail == 'node_killed twist_mux: at rest 0.92 s after, goals reached'
    # At rest only 1.20 s after: too late; never: fails too.
    late = track([0.5] * 109 + [0.0] * 2 + [0.5] * 89)
    result = judge_reaction(killed, late, LIVE, goals_reached=True)
    assert not result.passed and 'came to rest only 1.20 s after' in result.detail
    never = track([0.5] * 200)
    assert 'came to rest never' in judge_reaction(killed, never, LIVE, True).detail


def test_the_verdict_has_a_fault_reaction_line(tmp_path):
    path = Path(tmp_path) / 'faulty.yaml'
    path.write_text("""
scenario:
  name: faulty
  world: apartment
  steps:
  - fault: {kind: lidar_blinded, duration_s: 2.0, onset_s: 1.0}
  - goal: {x: 3.0, y: 2.0}
  criteria:
    stay_in_zone: false
    fault_reactions: true
""")
    scenario = load_scenario(path)
    assert scenario.criteria.fault_reactions
    record = RunRecord(
        truth=track([0.5] * 75 + [0.0] * 125), duration_s=4.0,
        step_results=[StepResult('fault', 'done', start_s=0.0, end_s=0.0),
                      StepResult('goal', 'reached', start_s=0.0, end_s=4.0)],
        faults=[blinded()],
        chain_states=LIVE + [(1.0, 'collision_monitor', 'STOP invalid source: scan blinded')])
    line = next(c for c in judge(scenario, record).criteria if c.name == 'fault_reaction')
    assert line.passed, line.detail
    record.step_results[1] = StepResult('goal', 'failed', start_s=0.0, end_s=4.0)
    line = next(c for c in judge(scenario, record).criteria if c.name == 'fault_reaction')
    assert not line.passed and 'a goal was not reached' in line.detail
    record.faults = []
    line = next(c for c in judge(scenario, record).criteria if c.name == 'fault_reaction')
    assert line.passed and line.detail == 'fault_reaction: no fault injected'


@pytest.mark.parametrize('value', ['"yes"', '1', 'null'])
def test_fault_reactions_must_be_a_boolean(tmp_path, value):
    path = Path(tmp_path) / 'bad.yaml'
    path.write_text(f"""
scenario:
  name: bad
  world: apartment
  steps:
  - wait: {{duration_s: 1.0}}
  criteria:
    fault_reactions: {value}
""")
    with pytest.raises(ValueError, match='criteria.fault_reactions'):
        load_scenario(path)


def test_a_stuck_encoder_is_judged_by_the_distance_travelled_while_it_acts():
    stuck = {'kind': 'encoder_stuck', 'wheel': 'FL', 'onset_s': 1.0, 'duration_s': 2.0,
             'began_s': 1.0, 'ended_s': 3.0}
    # 0.5 m/s from 0 to 2 s: 0.5 m after the onset (1 .. 2 s), then at rest.
    short = track([0.5] * 100 + [0.0] * 100)
    result = judge_reaction(stuck, short, LIVE, goals_reached=False)
    assert result.passed and result.detail == 'encoder_stuck: travelled 0.50 m while it acted'
    # 0.5 m/s to 2.6 s: 0.8 m, more than 0.6 m.
    far = track([0.5] * 130 + [0.0] * 70)
    result = judge_reaction(stuck, far, LIVE, goals_reached=False)
    assert not result.passed
    assert 'travelled 0.80 m while it acted (at most 0.6 m expected)' in result.detail


def test_amcl_diverged_may_drive_once_the_guard_finds_it_healthy_again():
    diverged = {'kind': 'amcl_diverged', 'onset_s': 1.0, 'duration_s': 0.0, 'began_s': 1.0,
                'ended_s': 1.0, 'applied': True}
    # At rest to 2.7 s, then driving: amcl converged at 2.6 s (+1.6 s), before the 3 s.
    truth = track([0.0] * 135 + [0.3] * 65)
    states = LIVE + [(1.1, 'zone_guard', 'STOP localisation unhealthy: position sigma 2.8 m'),
                     (1.3, 'zone_guard', 'ALLOW turning on the spot (localisation unhealthy)'),
                     (2.6, 'zone_guard', 'ALLOW')]
    assert judge_reaction(diverged, truth, states, goals_reached=True).passed
    # Still unhealthy when it drove: a failure.
    unhealthy = states[:-1]
    result = judge_reaction(diverged, truth, unhealthy, goals_reached=True)
    assert not result.passed and 'moving at 0.30 m/s at t=2.72 s' in result.detail
