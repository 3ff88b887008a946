"""Tests of the fault step: loading it, the runner's injection of faults, the driver's topics."""

import json
from pathlib import Path
import signal
import textwrap
import time

from mecanum_bringup.composition import compose, load_composition
from mecanum_bringup.launch_runner import default_composition_file
from mecanum_bringup.scenario_loader import load_scenario, ScenarioError
from mecanum_bringup.scenario_model import FaultStep, FreezeStep, RunRecord, WaitStep
from mecanum_bringup.scenario_runner import (
    composition_without, fault_nodes, FaultInjector, RunOptions, step_fault,
    write_composition, write_run_files)
from mecanum_bringup.system_description import load_system
import pytest
from robot_simulation.faults import FAULT_KINDS, FaultSpec

HEADER = 'scenario:\n  name: faulty\n  world: apartment\n  steps:\n  - wait: {duration_s: 1.0}\n'


def write(directory: Path, steps: str, name: str = 'faulty.yaml') -> Path:
    """Write a scenario whose first step is a wait and then steps (YAML list items)."""
    path = directory / name
    path.write_text(HEADER + textwrap.indent(textwrap.dedent(steps), '  '))
    return path


# --- loading ---------------------------------------------------------------------------

def test_a_fault_step_loads_with_its_parameters_and_defaults(tmp_path):
    scenario = load_scenario(write(tmp_path, """\
        - fault: {kind: encoder_stuck, wheel: RL, onset_s: 2, duration_s: 5}
        - fault: {kind: lidar_silent}
        - fault: {kind: kidnap, dx_m: 0.3, dyaw_rad: -0.2}
        - fault: {kind: node_frozen, node: amcl, onset_s: 1.5, duration_s: 6}
        - freeze: {node: zone_guard, duration_s: 4}
        """))
    wait, stuck, silent, kidnap, frozen, freeze = scenario.steps
    assert isinstance(wait, WaitStep)
    assert stuck == FaultStep(FaultSpec('encoder_stuck', 2.0, 5.0, (('wheel', 'RL'),)))
    assert stuck.kind == 'fault'
    assert stuck.describe() == 'fault encoder_stuck (wheel RL) at +2 s for 5 s'
    # No onset: at the step's start; no duration: to the end of the run.
    assert silent.fault == FaultSpec('lidar_silent', 0.0, None, ())
    assert silent.describe() == 'fault lidar_silent at +0 s to the end'
    # An instant: duration 0; parameters not given take their defaults.
    assert kidnap.fault == FaultSpec('kidnap', 0.0, 0.0,
                                     (('dx_m', 0.3), ('dy_m', 0.0), ('dyaw_rad', -0.2)))
    assert frozen.fault.where == 'runner' and frozen.fault.param('node') == 'amcl'
    # A freeze step is node_frozen at its step's start.
    assert freeze == FreezeStep('zone_guard', 4.0)
    assert freeze.as_fault() == FaultSpec('node_frozen', 0.0, 4.0, (('node', 'zone_guard'),))
    assert step_fault(freeze) == freeze.as_fault() and step_fault(stuck) == stuck.fault
    assert step_fault(wait) is None


BAD_FAULTS = [
    ('- fault: {kind: laser_off}\n',
     'faulty.yaml: steps[1].fault.kind: must be one of lidar_blinded, lidar_frozen, '),
    ('- fault: {kind: lidar_blinded, wheel: FL}\n',
     'faulty.yaml: steps[1].fault.wheel: unknown key for lidar_blinded (allowed: kind, '
     'onset_s, duration_s)'),
    ('- fault: {kind: encoder_stuck}\n',
     'faulty.yaml: steps[1].fault.wheel: required for encoder_stuck'),
    ('- fault: {kind: encoder_stuck, wheel: XX}\n',
     "faulty.yaml: steps[1].fault.wheel: must be one of FL, FR, RL, RR, not 'XX'"),
    ('- fault: {kind: lidar_blinded, onset_s: -1}\n',
     'faulty.yaml: steps[1].fault.onset_s: must be a finite number of seconds >= 0, not -1'),
    ('- fault: {kind: lidar_blinded, duration_s: 0}\n',
     'faulty.yaml: steps[1].fault.duration_s: must be > 0 (or null: to the end), not 0'),
    ('- fault: {kind: node_killed, node: amcl, duration_s: 3}\n',
     'faulty.yaml: steps[1].fault.duration_s: node_killed is an instant, not 3'),
    ('- fault: {kind: serial_drop_bytes, rate: 2}\n',
     'faulty.yaml: steps[1].fault.rate: must be a probability in (0, 1], not 2'),
    ('- fault: lidar_blinded\n',
     "faulty.yaml: steps[1].fault: must be a mapping with a kind, not 'lidar_blinded'"),
    ('- fault: {kind: lidar_blinded}\n  timeout_s: 3\n',
     'faulty.yaml: steps[1].timeout_s: unknown key (allowed: fault)'),
    ('- fault: {kind: lidar_blinded}\n  wait: {duration_s: 1}\n',
     'faulty.yaml: steps[1]: needs exactly one of goal, waypoints, command, cmd_vel, wait, '
     'freeze, fault, got wait, fault'),
]


@pytest.mark.parametrize('steps, message', BAD_FAULTS)
def test_a_bad_fault_step_names_the_file_and_the_key(tmp_path, steps, message):
    with pytest.raises(ScenarioError) as caught:
        load_scenario(write(tmp_path, steps))
    assert str(caught.value).startswith(message), str(caught.value)


# --- the runner's injection ----------------------------------------------------------

class FakeSystem:
    """The launch runner's processes: node -> pid."""

    def __init__(self, pids):
        self.pids = pids

    def pid_of(self, node):
        return self.pids.get(node)


class FakeDriver:
    """Records what the runner sends (faults to the simulator, e-stop presses); reports."""

    def __init__(self):
        self.sent = []
        self.reports = []
        self.amcl_serves = True

    def fault_reports(self):
        return self.reports

    def send_fault(self, fault):
        self.sent.append(('fault', dict(fault)))

    def set_estop(self, engaged):
        self.sent.append(('estop', engaged))

    def keep_releasing(self):
        pass

    def process_down(self, name):
        self.sent.append(('down', name))

    def reinitialize_global_localization(self):
        self.sent.append(('global_localization', self.amcl_serves))
        return self.amcl_serves


@pytest.fixture
def injector():
    kills = []

    def kill(pid, number):
        if pid == 999:
            raise ProcessLookupError(pid)
        kills.append((pid, number))

    record = RunRecord()
    faults = FaultInjector(FakeSystem({'amcl': 101, 'twist_mux': 202, 'gone': 999}),
                           FakeDriver(), record, kill=kill)
    return faults, kills, record


def frozen(node, onset_s, duration_s):
    return FaultSpec('node_frozen', onset_s, duration_s, (('node', node),))


def test_runner_faults_act_at_their_simulated_times_in_order(injector):
    faults, kills, record = injector
    driver = faults.driver
    # Step 1 starts at 10 s: amcl frozen from 10 + 2 = 12 s to 12 + 5 = 17 s.
    faults.add(frozen('amcl', 2.0, 5.0), 10.0, 1)
    faults.due(11.99)
    assert kills == [] and record.faults[0]['began_s'] is None
    faults.due(12.0)
    assert kills == [(101, signal.SIGSTOP)]
    # The simulator's lockstep waits no longer for it.
    assert driver.sent == [('down', 'amcl')]
    driver.sent.clear()
    # Step 2 starts at 13 s: the e-stop at once (onset 0) for 3 s, to 16 s.
    faults.add(FaultSpec('estop', 0.0, 3.0), 13.0, 2)
    assert driver.sent == [('estop', True)]
    # Step 3 at 13 s: twist_mux killed at 13.5 s; a lidar fault goes to the simulator
    # at once with its absolute onset 13 + 1 = 14 s.
    faults.add(FaultSpec('node_killed', 0.5, 0.0, (('node', 'twist_mux'),)), 13.0, 3)
    faults.add(FaultSpec('lidar_blinded', 1.0, 4.0), 13.0, 4)
    assert driver.sent[1] == ('fault', {'kind': 'lidar_blinded', 'onset_s': 14.0,
                                        'duration_s': 4.0})
    # The first poll after 16 s: the kill (due 13.5) before the release (due 16).
    faults.due(16.2)
    assert kills[1:] == [(202, signal.SIGKILL)]
    assert driver.sent[2:] == [('down', 'twist_mux'), ('estop', False)]
    faults.due(16.99)
    assert len(kills) == 2
    faults.due(17.0)
    assert kills[2:] == [(101, signal.SIGCONT)]
    # A fault due after the run's end never acts. The simulator's are dated by its
    # reports (a step of 0.02 s after the onset), the kidnap with what became of it.
    faults.add(FaultSpec('lidar_silent', 30.0, None), 17.5, 5)
    kidnap = FaultSpec('kidnap', 0.0, 0.0, (('dx_m', 1.0), ('dy_m', 0.0), ('dyaw_rad', 0.0)))
    faults.add(kidnap, 17.5, 6)
    blinded = {'kind': 'lidar_blinded', 'onset_s': 14.0, 'duration_s': 4.0}
    driver.reports = [
        {'time_s': 0.0, 'active': [], 'started': [], 'ended': [], 'instants': []},
        {'time_s': 14.02, 'active': [blinded], 'started': [blinded], 'ended': [],
         'instants': []},
        {'time_s': 17.52, 'active': [blinded], 'started': [], 'ended': [], 'instants': [
            dict(kidnap.as_dict(), onset_s=17.5, applied=False, outcome='refused: wall')]},
        {'time_s': 18.0, 'active': [], 'started': [], 'ended': [blinded], 'instants': []}]
    faults.finish()
    assert [(f['kind'], f['step'], f['where'], f['onset_s'], f['began_s'], f['ended_s'])
            for f in record.faults] == [
        ('node_frozen', 1, 'runner', 12.0, 12.0, 17.0),
        ('estop', 2, 'runner', 13.0, 13.0, 16.2),
        ('node_killed', 3, 'runner', 13.5, 16.2, 16.2),
        ('lidar_blinded', 4, 'simulator', 14.0, 14.02, 18.0),
        ('lidar_silent', 5, 'simulator', 47.5, None, None),
        ('kidnap', 6, 'simulator', 17.5, 17.52, 17.52)]
    assert (record.faults[5]['applied'], record.faults[5]['outcome']) == (
        False, 'refused: wall')
    assert record.faults[0]['node'] == 'amcl' and record.faults[0]['duration_s'] == 5.0
    json.dumps(record.faults)   # the summary's 'faults': plain types


def test_the_run_end_resumes_a_frozen_node_and_a_gone_process_is_no_error(injector):
    faults, kills, record = injector
    faults.add(frozen('amcl', 0.0, None), 3.0, 1)      # to the end of the run
    faults.add(FaultSpec('estop', 1.0, None), 3.0, 2)  # pressed, never released
    faults.add(frozen('gone', 0.0, 2.0), 3.0, 3)        # its process had exited
    assert kills == [(101, signal.SIGSTOP)]
    faults.due(4.0)
    assert faults.driver.sent == [('down', 'amcl'), ('estop', True)]
    faults.due(5.0)   # the gone process's end: nothing to resume
    assert kills == [(101, signal.SIGSTOP)]
    faults.finish()
    assert kills == [(101, signal.SIGSTOP), (101, signal.SIGCONT)]
    assert [(f['began_s'], f['ended_s']) for f in record.faults] == [
        (3.0, None), (4.0, None), (3.0, 5.0)]


def test_a_node_no_process_runs_is_an_error_at_the_fault_step(injector):
    faults, kills, _ = injector
    with pytest.raises(RuntimeError, match="node_killed: no running process runs node 'nav'"):
        faults.add(FaultSpec('node_killed', 5.0, 0.0, (('node', 'nav'),)), 0.0, 1)
    assert kills == []


def test_every_runner_kind_is_one_the_injector_applies():
    runner_kinds = {name for name, kind in FAULT_KINDS.items() if kind.where == 'runner'}
    assert runner_kinds == {'node_frozen', 'node_killed', 'estop', 'amcl_diverged'}


def test_amcl_diverged_asks_amcl_to_spread_its_particles_and_says_when_none_serves(injector):
    faults, kills, record = injector
    faults.add(FaultSpec('amcl_diverged', 2.0, 0.0), 10.0, 1)
    assert faults.driver.sent == []
    faults.due(12.0)
    assert faults.driver.sent == [('global_localization', True)]
    assert (record.faults[0]['began_s'], record.faults[0]['ended_s'],
            record.faults[0]['applied']) == (12.0, 12.0, True)
    faults.driver.amcl_serves = False      # e.g. slam:=true: no amcl
    faults.add(FaultSpec('amcl_diverged', 0.0, 0.0), 13.0, 2)
    assert (record.faults[1]['applied'], record.faults[1]['outcome']) == (
        False, 'no amcl serves reinitialize_global_localization')
    assert kills == []


# --- each faulted node in a process of its own ------------------------------------------

def test_faulted_nodes_leave_their_containers(tmp_path):
    assert composition_without({'a': ['x', 'y'], 'b': ['z']}, ['y', 'z']) == {'a': ['x']}
    scenario = load_scenario(write(tmp_path, """\
        - freeze: {node: amcl, duration_s: 2}
        - fault: {kind: node_killed, node: twist_mux}
        - fault: {kind: node_frozen, node: amcl, duration_s: 1}
        - fault: {kind: lidar_blinded}
        """))
    assert fault_nodes(scenario) == ['amcl', 'twist_mux']
    compose_it, path = write_composition(scenario, tmp_path)
    assert compose_it and path == tmp_path / 'composition.yaml'
    default = load_composition(default_composition_file())
    written = load_composition(path)
    assert written == composition_without(default, ['amcl', 'twist_mux'])
    assert 'amcl' in default['navigation_container'] and 'twist_mux' in default[
        'control_container']
    # The composed system runs them alone, the rest of their containers together.
    launch = write_run_files(scenario, tmp_path, RunOptions(tmp_path))
    labels = [node.label for node in compose(load_system(launch, {}), written).nodes]
    assert labels.count('amcl') == 1 and labels.count('twist_mux') == 1
    assert 'control_container' in labels and 'navigation_container' in labels
    assert 'collision_monitor' not in labels and 'map_server' not in labels
    # Without node faults: the default composition.
    plain = load_scenario(write(tmp_path, '- fault: {kind: imu_silent}\n', 'plain.yaml'))
    assert write_composition(plain, tmp_path / 'plain') == (True, None)


# --- the driver's topics ---------------------------------------------------------------

def test_the_driver_sends_faults_and_the_estop_to_late_joiners(monkeypatch):
    import rclpy
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Bool, String
    from mecanum_bringup.isolation import lease_domain_id
    from mecanum_bringup.scenario_driver import ScenarioDriver
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    with lease_domain_id() as lease:
        driver = ScenarioDriver(lease.domain_id)
        context = rclpy.Context()
        try:
            fault = {'kind': 'wheel_slip', 'onset_s': 12.5, 'duration_s': None,
                     'wheel': 'FR', 'traction_factor': 0.2}
            driver.send_fault(fault)
            driver.set_estop(True)
            # Subscribers that join afterwards, with the QoS the simulator (reliable,
            # transient_local) and twist_mux and motor_controller (default) use.
            rclpy.init(context=context, domain_id=lease.domain_id)
            node = rclpy.create_node('listener', context=context)
            faults, estops = [], []
            node.create_subscription(String, 'simulator/faults', faults.append, QoSProfile(
                depth=10, reliability=ReliabilityPolicy.RELIABLE,
                durability=DurabilityPolicy.TRANSIENT_LOCAL))
            node.create_subscription(Bool, 'emergency_stop', estops.append, QoSProfile(
                depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL))
            executor = rclpy.executors.SingleThreadedExecutor(context=context)
            executor.add_node(node)
            deadline = time.monotonic() + 30.0
            while (not faults or not estops) and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.1)
            assert [json.loads(m.data) for m in faults] == [fault]
            assert [m.data for m in estops] == [True]
            driver.set_estop(False)
            while len(estops) < 2 and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.1)
            assert [m.data for m in estops] == [True, False]
            # The simulator's report of its faults (latched, depth 1, as it publishes).
            reports = node.create_publisher(String, 'simulator/active_faults', QoSProfile(
                depth=1, reliability=ReliabilityPolicy.RELIABLE,
                durability=DurabilityPolicy.TRANSIENT_LOCAL))
            report = {'time_s': 12.52, 'active': [fault], 'started': [fault], 'ended': [],
                      'instants': []}
            reports.publish(String(data=json.dumps(report)))
            while not driver.fault_reports() and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.1)
            assert driver.fault_reports() == [report]
        finally:
            driver.close()
            executor.shutdown()
            rclpy.try_shutdown(context=context)


def test_the_driver_asks_for_the_reset_again_when_it_overtook_the_release(monkeypatch):
    """
    The reset call can reach motor_controller before the false: asked again until done.

    Found by the fault sweep: motor_controller refused the reset ('emergency_stop is
    still true'), the stop stayed latched and the rest of the run's goals timed out.
    """
    import rclpy
    from std_srvs.srv import Trigger
    from mecanum_bringup.isolation import lease_domain_id
    from mecanum_bringup.scenario_driver import ESTOP_RELEASE_SERVICE, ScenarioDriver
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    with lease_domain_id() as lease:
        context = rclpy.Context()
        rclpy.init(context=context, domain_id=lease.domain_id)
        node = rclpy.create_node('motor_controller_stand_in', context=context)
        calls = []

        def release(request, response):
            calls.append(time.monotonic())
            response.success = len(calls) >= 2   # the first overtook the false
            response.message = 'released' if response.success else 'still true'
            return response

        node.create_service(Trigger, ESTOP_RELEASE_SERVICE, release)
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        driver = ScenarioDriver(lease.domain_id)
        try:
            deadline = time.monotonic() + 30.0
            while not driver._estop_release.service_is_ready() and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.1)
            driver.set_estop(True)
            driver.set_estop(False)
            while len(calls) < 2 and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.1)
                driver.keep_releasing()
            assert len(calls) == 2
            # Accepted: no more calls however often it is asked.
            settle = time.monotonic() + 1.0
            while time.monotonic() < settle:
                executor.spin_once(timeout_sec=0.05)
                driver.keep_releasing()
            assert len(calls) == 2
        finally:
            driver.close()
            executor.shutdown()
            rclpy.try_shutdown(context=context)
