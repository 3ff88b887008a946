"""Tests of mecanum_bringup.scenario_runner's files: the system a scenario runs (real files)."""

from pathlib import Path

from mecanum_bringup.scenario_loader import load_scenario
from mecanum_bringup.scenario_runner import RunOptions, write_run_files
from mecanum_bringup.system_description import load_system
from mecanum_safety.zone import load_zone_file
import pytest
import yaml

SCENARIOS = Path(__file__).resolve().parents[1] / 'scenarios'


def labels(system):
    """Return the node labels of a loaded system."""
    return [node.label for node in system.nodes]


def parameter(node, name):
    """Return the last override of parameter name given to a node (None when absent)."""
    values = [value for item in node.parameters if isinstance(item, tuple)
              for key, value in [item] if key == name]
    return values[-1] if values else None


def test_a_scenario_runs_the_whole_robot_in_its_world_with_its_zone(tmp_path):
    scenario = load_scenario(SCENARIOS / 'goal_outside_zone_refused.yaml')
    launch = write_run_files(scenario, tmp_path, RunOptions(tmp_path))
    system = load_system(launch, {})
    names = labels(system)
    for node in ('simulator', 'hardware_interface', 'ekf_filter_node', 'map_server', 'amcl',
                 'navigator', 'velocity_smoother', 'twist_mux', 'collision_monitor',
                 'zone_guard', 'motor_controller', 'robot_controller'):
        assert names.count(node) == 1, (node, names)
    assert 'bag_recorder' not in names and 'foxglove_bridge' not in names
    # The world the simulator loads: the spawn and zone of the scenario.
    world = yaml.safe_load((tmp_path / 'world.yaml').read_text())['world']
    start = world['robot_start']
    assert (start['x_m'], start['y_m']) == pytest.approx(scenario.spawn[:2])
    assert world['test_zone'] == scenario.authorised_zone.to_document()
    simulator = system.nodes[names.index('simulator')]
    assert parameter(simulator, 'world') == str(tmp_path / 'world.yaml')
    # The navigator, the zone guard and robot_controller get the same zone, in one file.
    assert load_zone_file(tmp_path / 'zone.yaml') == scenario.authorised_zone
    for node in ('navigator', 'zone_guard', 'robot_controller'):
        assert parameter(system.nodes[names.index(node)], 'zone_file') == \
            str(tmp_path / 'zone.yaml'), node
    navigator = system.nodes[names.index('navigator')]
    assert tmp_path / 'nav2_params.yaml' in navigator.parameters
    # motor_controller takes only the chain's output.
    motor = system.nodes[names.index('motor_controller')]
    assert ('cmd_vel', 'cmd_vel_safe') in motor.remappings
    # amcl starts where the robot is, with a small spread.
    amcl = system.nodes[names.index('amcl')]
    assert parameter(amcl, 'initial_pose.x') == pytest.approx(scenario.initial_pose[0])
    assert parameter(amcl, 'initial_pose.std_xy') == pytest.approx(0.05)


def test_recording_live_view_and_speed_are_options(tmp_path):
    scenario = load_scenario(SCENARIOS / 'text_commands.yaml')
    options = RunOptions(tmp_path, real_time_factor=2.5, record=True, foxglove=True)
    system = load_system(write_run_files(scenario, tmp_path, options), {})
    names = labels(system)
    assert names.count('bag_recorder') == 1 and names.count('foxglove_bridge') == 1
    recorder = system.nodes[names.index('bag_recorder')]
    assert parameter(recorder, 'output') == str(tmp_path / 'bag')
    assert parameter(recorder, 'use_sim_time') is True
    simulator = system.nodes[names.index('simulator')]
    assert parameter(simulator, 'real_time_factor') == pytest.approx(2.5)
    assert parameter(simulator, 'sensor_noise_scale') == pytest.approx(1.0)


def test_the_sensor_noise_scale_reaches_the_simulator(tmp_path):
    path = tmp_path / 'noisy.yaml'
    path.write_text((SCENARIOS / 'text_commands.yaml').read_text().replace(
        '  world: apartment\n', '  world: apartment\n  sensor_noise_scale: 3.0\n'))
    scenario = load_scenario(path)
    system = load_system(write_run_files(scenario, tmp_path, RunOptions(tmp_path)), {})
    simulator = system.nodes[labels(system).index('simulator')]
    assert parameter(simulator, 'sensor_noise_scale') == pytest.approx(3.0)
