"""Hand-worked tests of the simulator's fault injection (robot_simulation.fault_injection)."""

import json
import math

import numpy as np
import pytest
from robot_simulation.fault_injection import (
    effects_of, FaultChange, FaultEffects, FaultSchedule, kidnap_target, NO_EFFECTS,
    parse_fault_message, ScanFaults)
from robot_simulation.faults import FaultError, parse_fault


def fault(**raw):
    """Return the FaultSpec of a mapping (onset_s 0 unless given)."""
    return parse_fault(raw)


# ---------------------------------------------------------------- effects


def test_no_fault_has_no_effect():
    assert effects_of([]) == NO_EFFECTS == FaultEffects()
    assert NO_EFFECTS.imu_bias_sample() is None
    assert NO_EFFECTS.traction_factors == (1.0, 1.0, 1.0, 1.0)


def test_effects_of_one_fault_of_each_kind():
    assert effects_of([fault(kind='lidar_blinded')]).lidar_blinded
    assert effects_of([fault(kind='lidar_frozen')]).lidar_frozen
    assert effects_of([fault(kind='lidar_silent')]).lidar_silent
    assert effects_of([fault(kind='imu_silent')]).imu_silent
    assert effects_of([fault(kind='scan_stamp_skew', offset_s=-0.25)]).scan_stamp_offset_s \
        == -0.25
    bias = effects_of([fault(kind='imu_bias', gyro_z_rad_s=0.02, accel_x_m_s2=0.3)])
    assert bias.imu_bias == (0.02, 0.3, 0.0)
    # A board sample is (ax, ay, az, gx, gy, gz).
    assert bias.imu_bias_sample() == (0.3, 0.0, 0.0, 0.0, 0.0, 0.02)
    assert effects_of([fault(kind='encoder_stuck', wheel='RL')]).stuck_wheels == {2}
    assert effects_of([fault(kind='wheel_slip', wheel='FR')]).traction_factors == (
        1.0, 0.2, 1.0, 1.0)   # the default traction_factor
    line = effects_of([fault(kind='serial_drop_bytes', rate=0.3),
                       fault(kind='serial_bit_flips', rate=0.01),
                       fault(kind='serial_latency', latency_s=0.05)])
    assert (line.serial_drop_rate, line.serial_flip_rate, line.serial_latency_s) == (
        pytest.approx(0.3), pytest.approx(0.01), 0.05)
    # An instant does nothing while acting: it is applied once, at its onset.
    assert effects_of([fault(kind='kidnap', dx_m=1.0)]) == NO_EFFECTS


def test_faults_acting_together_combine():
    """
    Flags stay flags, offsets, biases and latencies add, traction factors multiply.

    Drops 0.5 and 0.2: a byte gets through both with 0.5 * 0.8 = 0.4, so 0.6 is lost.
    """
    effects = effects_of([
        fault(kind='scan_stamp_skew', offset_s=0.1), fault(kind='scan_stamp_skew', offset_s=0.2),
        fault(kind='imu_bias', gyro_z_rad_s=0.01), fault(kind='imu_bias', gyro_z_rad_s=0.03),
        fault(kind='encoder_stuck', wheel='FL'), fault(kind='encoder_stuck', wheel='RR'),
        fault(kind='encoder_stuck', wheel='FL'),
        fault(kind='wheel_slip', wheel='FL', traction_factor=0.5),
        fault(kind='wheel_slip', wheel='FL', traction_factor=0.2),
        fault(kind='serial_drop_bytes', rate=0.5), fault(kind='serial_drop_bytes', rate=0.2),
        fault(kind='serial_latency', latency_s=0.01), fault(kind='serial_latency', latency_s=0.02),
        fault(kind='lidar_blinded'), fault(kind='lidar_blinded')])
    assert effects.scan_stamp_offset_s == pytest.approx(0.3)
    assert effects.imu_bias == (pytest.approx(0.04), 0.0, 0.0)
    assert effects.stuck_wheels == {0, 3}
    assert effects.traction_factors == (pytest.approx(0.1), 1.0, 1.0, 1.0)
    assert effects.serial_drop_rate == pytest.approx(0.6)
    assert effects.serial_latency_s == pytest.approx(0.03)
    assert effects.lidar_blinded and not effects.lidar_frozen


# ---------------------------------------------------------------- the lidar's output


def test_scan_faults_blind_silence_and_freeze():
    faults = ScanFaults()
    first, second = np.array([1.0, 2.0], np.float32), np.array([3.0, np.inf], np.float32)
    assert faults.apply(NO_EFFECTS, first) is first
    blinded = faults.apply(FaultEffects(lidar_blinded=True), first)
    assert blinded.dtype == np.float32 and blinded.tolist() == [math.inf, math.inf]
    assert first.tolist() == [1.0, 2.0]   # the scan itself is left alone
    assert faults.apply(FaultEffects(lidar_silent=True), first) is None
    frozen = FaultEffects(lidar_frozen=True)
    assert faults.apply(frozen, first).tolist() == [1.0, 2.0]
    first[0] = 9.0   # the held scan is a copy
    assert faults.apply(frozen, second).tolist() == [1.0, 2.0]
    # Blinded beats frozen; silent beats both, and the freeze still holds its scan.
    assert faults.apply(FaultEffects(lidar_frozen=True, lidar_blinded=True),
                        second).tolist() == [math.inf, math.inf]
    assert faults.apply(FaultEffects(lidar_frozen=True, lidar_silent=True), second) is None
    assert faults.apply(frozen, second).tolist() == [1.0, 2.0]
    # A freeze that ends forgets its scan; the next freeze holds the scan of its onset.
    assert faults.apply(NO_EFFECTS, second) is second
    assert faults.apply(frozen, second).tolist() == [3.0, math.inf]


# ---------------------------------------------------------------- the schedule


def test_schedule_timeline_hand_worked():
    """
    Lidar blinded 1..3 s, a kidnap at 1.5 s, FL stuck from 2 s to the end.

    Updates are due at 1.0 (blinded on), 1.5 (kidnap), 2.0 (stuck on), 3.0 (blinded off),
    then never.
    """
    schedule = FaultSchedule()
    blinded = fault(kind='lidar_blinded', onset_s=1.0, duration_s=2.0)
    kidnap = fault(kind='kidnap', onset_s=1.5, dx_m=0.5)
    stuck = fault(kind='encoder_stuck', onset_s=2.0, wheel='FL')
    assert schedule.next_change_s == math.inf
    for item in (blinded, kidnap, stuck):
        assert schedule.add(item, 0.2) is None
    assert schedule.next_change_s == 1.0
    assert schedule.update(0.995) is None
    change = schedule.update(1.0)
    assert (change.started, change.ended, change.instants) == ([blinded], [], [])
    assert change.active == (blinded,) and change.effects.lidar_blinded
    assert schedule.next_change_s == 1.5
    change = schedule.update(1.5)
    assert (change.started, change.ended, change.instants) == ([], [], [kidnap])
    assert change.active == (blinded,)
    assert schedule.next_change_s == 2.0
    change = schedule.update(2.0)
    assert change.started == [stuck] and change.active == (blinded, stuck)
    assert change.effects == FaultEffects(lidar_blinded=True, stuck_wheels=frozenset({0}))
    assert schedule.next_change_s == 3.0
    change = schedule.update(3.0)
    assert (change.started, change.ended) == ([], [blinded])
    assert schedule.active == (stuck,) and schedule.effects.stuck_wheels == {0}
    assert schedule.next_change_s == math.inf
    assert schedule.pending == (stuck,)


def test_schedule_effects_return_to_no_effects_object():
    """After the last fault ends the effects are NO_EFFECTS itself (the fast path)."""
    schedule = FaultSchedule()
    schedule.add(fault(kind='lidar_silent', onset_s=0.0, duration_s=0.5), 0.0)
    schedule.update(0.0)
    assert schedule.effects.lidar_silent
    schedule.update(0.5)
    assert schedule.effects is NO_EFFECTS and schedule.active == ()


def test_schedule_takes_late_faults_and_refuses_runner_kinds():
    schedule = FaultSchedule()
    # Over already: not scheduled, and the caller learns why.
    note = schedule.add(fault(kind='lidar_silent', onset_s=1.0, duration_s=2.0), 3.0)
    assert note == ('fault lidar_silent at 1 s for 2 s is over already at 3.0 s: '
                    'not injected')
    assert schedule.pending == () and schedule.next_change_s == math.inf
    # Onset passed, still acting: it starts at the next update, and says it was late.
    late = fault(kind='lidar_silent', onset_s=1.0, duration_s=2.0)
    assert schedule.add(late, 2.5) is None
    assert schedule.next_change_s == 1.0
    change = schedule.update(2.505)
    assert change.started == [late]
    assert change.log_lines() == [
        ('info', 'fault lidar_silent on at 2.505 s for 2 s (onset 1.0 s)')]
    # A fault shorter than the time between two updates is reported on and off.
    brief = fault(kind='lidar_blinded', onset_s=2.506, duration_s=0.001)
    schedule.add(brief, 2.505)
    change = schedule.update(2.51)
    assert (change.started, change.ended) == ([brief], [brief])
    with pytest.raises(FaultError, match='scenario runner'):
        schedule.add(fault(kind='estop', duration_s=1.0), 0.0)


def test_log_lines_and_report():
    blinded = fault(kind='lidar_blinded', onset_s=12.0, duration_s=3.0)
    stuck = fault(kind='encoder_stuck', onset_s=12.0, wheel='FL')
    kidnap = fault(kind='kidnap', onset_s=12.0, dx_m=1.0)
    change = FaultChange(12.0, started=[blinded, stuck], active=(blinded, stuck))
    change.outcomes.append((kidnap, None, 'the robot moved'))
    assert change.log_lines() == [
        ('info', 'fault lidar_blinded on at 12.0 s for 3 s'),
        ('info', 'fault encoder_stuck (wheel FL) on at 12.0 s until the end'),
        ('info', 'fault kidnap (dx_m 1, dy_m 0, dyaw_rad 0) at 12.0 s: the robot moved')]
    report = json.loads(json.dumps(change.report()))
    assert report['time_s'] == 12.0
    assert [item['kind'] for item in report['active']] == ['lidar_blinded', 'encoder_stuck']
    assert report['active'][1] == {'kind': 'encoder_stuck', 'onset_s': 12.0,
                                   'duration_s': None, 'wheel': 'FL'}
    assert report['ended'] == []
    assert report['instants'] == [dict(kidnap.as_dict(), applied=True,
                                       outcome='the robot moved')]
    ended = FaultChange(15.0, ended=[blinded])
    ended.outcomes.append((kidnap, 'a wall', 'refused: a wall'))
    assert ended.log_lines() == [
        ('info', 'fault lidar_blinded off at 15.0 s'),
        ('error', 'fault kidnap (dx_m 1, dy_m 0, dyaw_rad 0) at 15.0 s: refused: a wall')]
    assert ended.report()['instants'][0]['applied'] is False
    assert FaultChange(0.0).report() == {'time_s': 0.0, 'active': [], 'started': [],
                                         'ended': [], 'instants': []}


# ---------------------------------------------------------------- kidnap


def test_kidnap_target_moves_in_the_world_and_wraps_the_yaw():
    kidnap = fault(kind='kidnap', dx_m=1.0, dy_m=-0.5, dyaw_rad=1.0)
    x, y, yaw = kidnap_target((2.0, 3.0, math.pi - 0.5), kidnap)
    assert (x, y) == (3.0, 2.5)
    assert yaw == pytest.approx(0.5 - math.pi)


# ---------------------------------------------------------------- control messages


def test_parse_fault_message_takes_an_object_or_a_list():
    one = parse_fault_message('{"kind": "lidar_blinded", "onset_s": 12, "duration_s": 3}')
    assert one == [fault(kind='lidar_blinded', onset_s=12.0, duration_s=3.0)]
    two = parse_fault_message(json.dumps([
        {'kind': 'encoder_stuck', 'onset_s': 1.5, 'wheel': 'FL'},
        {'kind': 'serial_drop_bytes', 'onset_s': 2, 'duration_s': 0.5, 'rate': 0.3}]))
    assert [item.kind for item in two] == ['encoder_stuck', 'serial_drop_bytes']
    assert two[1].param('rate') == 0.3


@pytest.mark.parametrize('text, reason', [
    ('{"kind": "lidar_blinded"', 'not JSON'),
    ('[]', 'non-empty list'),
    ('3', 'JSON object'),
    ('{"kind": ["lidar_blinded"]}', r'fault\.kind: must be one of'),
    ('{"kind": "lidar_blinded", "onset_s": -1}', r'fault\.onset_s'),
    ('[{"kind": "lidar_silent"}, {"kind": "serial_drop_bytes", "rate": 2}]',
     r'faults\[1\]\.rate'),
    ('[{"kind": "lidar_silent"}, {"kind": "node_killed", "node": "amcl"}]',
     r'faults\[1\]\.kind: node_killed is injected by the scenario runner'),
    ('{"kind": "estop", "duration_s": 1}', 'scenario runner'),
])
def test_parse_fault_message_refuses_the_whole_message_naming_the_fault(text, reason):
    with pytest.raises(FaultError, match=reason):
        parse_fault_message(text)
