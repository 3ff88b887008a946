"""
Integration: faults injected into the running simulator through ``simulator/faults``.

simulation.launch.yaml (robot_simulation) starts the simulator (lockstep) with the
control stack and the command chain, as tests/test_simulation.py does. The test sends
faults as the scenario runner will (JSON on ``simulator/faults``, reliable, transient
local; onset absolute in simulated seconds) and watches the stack's own outputs: the
published scans, encoder_reader's joint_states and hardware_interface's /diagnostics.
Each fault starts about 1 s of simulated time after it is sent and lasts under 1 s.
"""

import json
import math

from diagnostic_msgs.msg import DiagnosticArray
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState, LaserScan
from std_msgs.msg import String

pytestmark = pytest.mark.integration

#: The control topic's QoS (simulator_node): reliable, transient local, depth 50.
FAULTS_QOS = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: The nodes a command passes through on its way to the board (tests/test_simulation.py).
COMMAND_PATH = ('twist_mux', 'collision_monitor', 'zone_guard', 'motor_controller',
                'velocity_controller', 'hardware_interface')
LINK_STATUS = 'mecanum_control: ESP32 link'


def stamp_s(message) -> float:
    """Return a message's header stamp in seconds."""
    return message.header.stamp.sec + message.header.stamp.nanosec * 1e-9


def link_values(message) -> dict:
    """Return {key: value} of hardware_interface's link status ({} if absent)."""
    for status in message.status:
        if status.name == LINK_STATUS:
            return {item.key: item.value for item in status.values}
    return {}


@pytest.fixture
def simulation(start_system, test_node, tmp_path):
    """Start the apartment simulation in lockstep; return (system, test_node, faults pub)."""
    system = start_system('robot_simulation', 'simulation.launch.yaml', 'world:=apartment',
                          'lockstep:=true', f'board_port:={tmp_path / "ttySIM"}',
                          f'estop_latch_file:={tmp_path / "estop"}')
    system.wait_for_line(r'\[hardware_interface\].*Connected to the board', timeout=60)
    system.wait_for_line(r'\[velocity_controller\].*control active', timeout=60)
    system.wait_for_line(r'\[simulator\].*lockstep: the board .* answers', timeout=60)
    for node in COMMAND_PATH:
        system.wait_for_line(rf'\[simulator\].*lockstep: {node}( \(\+\d+ nodes\))? takes part',
                             timeout=60)
    publisher = test_node.node.create_publisher(String, 'simulator/faults', FAULTS_QOS)
    return system, test_node, publisher


def send(publisher, fault) -> None:
    """Publish one fault (or a list of them) as the JSON control message."""
    publisher.publish(String(data=json.dumps(fault)))


def test_blinded_lidar_stuck_encoder_and_a_lossy_serial_line(simulation):
    system, test_node, faults = simulation
    active = test_node.record(String, 'simulator/active_faults', latched=True)
    assert json.loads(active.wait_for(lambda m: True).data)['active'] == []

    # Bad messages are refused with the reason, and the simulator runs on.
    send(faults, {'kind': 'node_killed', 'node': 'amcl'})
    system.wait_for_line(r'\[simulator\].*fault message ignored: fault\.kind: node_killed is '
                         'injected by the scenario runner')
    faults.publish(String(data='{"kind": "lidar_blinded", "rate": 1}'))
    system.wait_for_line(r'\[simulator\].*fault message ignored: fault\.rate: unknown key')

    # 1. The lidar blinded for 1 s: every range +inf, then the walls again. The onset
    #    lies between two scans (10 Hz, at whole tenths of a second).
    scans = test_node.record(LaserScan, 'scan')
    now = stamp_s(scans.wait_for(lambda m: True))
    onset = round(now, 1) + 1.05
    send(faults, {'kind': 'lidar_blinded', 'onset_s': onset, 'duration_s': 1.0})
    scans.wait_for(lambda m: stamp_s(m) > onset + 1.5, timeout=60)
    system.wait_for_line(r'\[simulator\].*fault lidar_blinded on at [\d.]+ s for 1 s')
    system.wait_for_line(r'\[simulator\].*fault lidar_blinded off at [\d.]+ s')
    before = scans.messages_between(onset - 0.5, onset)
    during = scans.messages_between(onset, onset + 1.0)
    after = scans.messages_between(onset + 1.0, onset + 1.5)
    print(f'scans before/during/after the blinding: {len(before)}, {len(during)}, '
          f'{len(after)}')
    assert len(during) == 10 and len(before) >= 4 and len(after) >= 4
    assert all(all(r == math.inf for r in scan.ranges) for scan in during)
    for scan in before + after:
        assert sum(math.isfinite(r) for r in scan.ranges) > 300
    on = active.wait_for(lambda m: [f['kind'] for f in json.loads(m.data)['started']]
                         == ['lidar_blinded'])
    assert [f['kind'] for f in json.loads(on.data)['active']] == ['lidar_blinded']
    off = active.wait_for(lambda m: [f['kind'] for f in json.loads(m.data)['ended']]
                          == ['lidar_blinded'])
    assert json.loads(off.data)['active'] == []
    assert json.loads(off.data)['time_s'] == pytest.approx(onset + 1.0, abs=0.006)

    # 2. FL's encoder stuck for 0.8 s while the robot drives forward at 0.15 m/s:
    #    joint_states' FL angle holds still while the other wheels turn on.
    joints = test_node.record(JointState, 'joint_states')
    drive = test_node.twist_repeater('cmd_vel')
    drive.twist = (0.15, 0.0, 0.0)
    drive.start()
    try:
        moving = joints.wait_for(lambda m: len(m.velocity) == 4 and min(m.velocity) > 2.0,
                                 timeout=60)
        onset = stamp_s(moving) + 1.0
        send(faults, {'kind': 'encoder_stuck', 'onset_s': onset, 'duration_s': 0.8,
                      'wheel': 'FL'})
        joints.wait_for(lambda m: stamp_s(m) > onset + 1.0, timeout=60)
    finally:
        drive.twist = (0.0, 0.0, 0.0)
    system.wait_for_line(r'\[simulator\].*fault encoder_stuck \(wheel FL\) on at [\d.]+ s '
                         r'for 0\.8 s')
    fl = moving.name.index('front_left_wheel_joint')
    stuck = joints.messages_between(onset + 0.05, onset + 0.75)
    assert len(stuck) >= 20
    assert len({m.position[fl] for m in stuck}) == 1, 'FL moved while its encoder was stuck'
    for wheel in range(4):
        if wheel != fl:
            turned = stuck[-1].position[wheel] - stuck[0].position[wheel]
            print(f'wheel {moving.name[wheel]} turned {turned:.2f} rad while FL was stuck')
            assert turned > 0.5   # 0.7 s at up to 3.75 rad/s (FL pulls the robot round)
    drive.stop()

    # 3. 0.4 s of a serial line losing 30 % of its bytes both ways (shorter than
    #    hardware_interface's link timeout, 0.5 s):
    #    hardware_interface counts bad frames from the board, the board counts bad ones
    #    from hardware_interface (its BOARD_STATUS, on /diagnostics too).
    diagnostics = test_node.record(DiagnosticArray, '/diagnostics')
    first = diagnostics.wait_for(lambda m: link_values(m), timeout=30)
    errors_before = int(link_values(first)['frame_errors'])
    board_bad_before = int(link_values(first).get('board_rx_bad_frames', 0))
    onset = stamp_s(first) + 1.0
    send(faults, {'kind': 'serial_drop_bytes', 'onset_s': onset, 'duration_s': 0.4,
                  'rate': 0.3})
    report = diagnostics.wait_for(
        lambda m: stamp_s(m) > onset + 0.4
        and int(link_values(m).get('frame_errors', 0)) > errors_before + 10
        and int(link_values(m).get('board_rx_bad_frames', 0)) > board_bad_before,
        timeout=60)
    print(f'after the lossy line: {link_values(report)}')
    system.wait_for_line(r'\[simulator\].*fault serial_drop_bytes \(rate 0\.3\) on at [\d.]+ '
                         r's for 0\.4 s')
    system.wait_for_line(r'\[simulator\].*fault serial_drop_bytes \(rate 0\.3\) off at')
    # The line is clean again: frames come through and time runs on in lockstep.
    later = diagnostics.wait_for(
        lambda m: stamp_s(m) > stamp_s(report) + 1.5 and link_values(m), timeout=60)
    assert int(link_values(later)['frames_ok']) > int(link_values(report)['frames_ok'])
    assert 'disconnected' not in ' '.join(s.message for s in later.status)
