"""Tests of composition (nodes grouped into container processes), without ROS."""

import json
from pathlib import Path
import textwrap

from mecanum_bringup.composition import compose, load_composition
from mecanum_bringup.launch_runner import default_composition_file
from mecanum_bringup.node_container import CompositionError, node_class, parse_spec
from mecanum_bringup.system_description import (
    default_find_package_share, load_system, NodeProcess, System, SystemDescriptionError)
import pytest


def write(path: Path, text: str) -> Path:
    path.write_text(textwrap.dedent(text), encoding='utf-8')
    return path


def node(label, **fields) -> NodeProcess:
    return NodeProcess(package='pkg', executable=label, name=label, **fields)


def test_load_composition_reads_containers(tmp_path):
    path = write(tmp_path / 'c.yaml', """
        containers:
          a: [one, two]
          b: [three]
        """)
    assert load_composition(path) == {'a': ['one', 'two'], 'b': ['three']}


@pytest.mark.parametrize('text, message', [
    ('containers: {}\n', 'expected a mapping'),
    ('[1, 2]\n', 'expected a mapping'),
    ('containers: {a: [x], b: [x]}\n', "node 'x' is in both a and b"),
    ('containers: {a: []}\n', 'containers.a must be a non-empty list'),
    ('containers: {a: [x, 3]}\n', 'containers.a must be a non-empty list'),
    ('containers: {"not a name": [x]}\n', 'is not a plain name'),
    ('containers: {a: [x\n', 'cannot read the composition'),
])
def test_load_composition_rejects_bad_files(tmp_path, text, message):
    path = tmp_path / 'bad.yaml'
    path.write_text(text, encoding='utf-8')
    with pytest.raises(SystemDescriptionError, match=message) as error:
        load_composition(path)
    assert str(path) in str(error.value)


def test_compose_groups_nodes_in_place_and_keeps_their_arguments():
    sim = node('sim')
    a = node('a', parameters=[Path('/p/a.yaml'), ('use_sim_time', True)],
             remappings=[('cmd_vel', 'cmd_vel_nav')], respawn=True, respawn_delay_s=1.0)
    b = node('b', respawn=True, respawn_delay_s=2.0)
    c = node('c', shutdown_on_exit=True)
    system = System(nodes=[sim, a, b, c], arguments={'x': '1'})
    composed = compose(system, {'box': ['b', 'a', 'missing'], 'solo': ['c']})
    assert [n.label for n in composed.nodes] == ['sim', 'box', 'solo']
    box = composed.nodes[1]
    assert (box.package, box.executable) == ('mecanum_bringup', 'node_container')
    assert box.respawn and box.respawn_delay_s == 2.0 and not box.shutdown_on_exit
    assert composed.nodes[2].shutdown_on_exit and not composed.nodes[2].respawn
    # The container's one argument lists its nodes in the composition's order (the
    # order they start in), each with the --ros-args it would have had on its own.
    spec = json.loads(box.arguments[0])
    assert [s['label'] for s in spec] == ['b', 'a']
    assert spec[1]['ros_args'] == a.ros_args() == [
        '--ros-args', '-r', '__node:=a', '--params-file', '/p/a.yaml',
        '-p', 'use_sim_time:=true', '-r', 'cmd_vel:=cmd_vel_nav']
    assert composed.arguments == {'x': '1'}
    assert [n.label for n in system.nodes] == ['sim', 'a', 'b', 'c']  # not modified


def test_nodes_that_cannot_share_a_process_stay_alone():
    prefixed = node('p', launch_prefix=['valgrind'])
    with_args = node('w', arguments=['--flag'])
    plain = node('q')
    composed = compose(System(nodes=[prefixed, with_args, plain]), {'box': ['p', 'w', 'q']})
    assert [n.label for n in composed.nodes] == ['p', 'w', 'box']


def test_nodes_with_different_environments_are_an_error():
    system = System(nodes=[node('a', env={'X': '1'}), node('b', env={'X': '2'})])
    with pytest.raises(SystemDescriptionError, match='do not share one environment'):
        compose(system, {'box': ['a', 'b']})


def test_the_robot_composes_into_four_processes():
    """The project's composition file on the real robot system (simulated)."""
    system = load_system(Path(default_find_package_share('mecanum_bringup')) / 'launch'
                         / 'robot.launch.yaml')
    composed = compose(system, load_composition(default_composition_file()))
    assert [n.label for n in composed.nodes] == [
        'simulator', 'control_container', 'navigation_container']
    members = {n.label: [s['label'] for s in json.loads(n.arguments[0])]
               for n in composed.nodes if n.executable == 'node_container'}
    assert set(members['control_container']) >= {
        'hardware_interface', 'velocity_controller', 'ekf_filter_node', 'collision_monitor'}
    assert members['navigation_container'] == ['map_server', 'amcl', 'navigator']
    # Every node of the system is somewhere, once.
    labels = [label for group in members.values() for label in group] + ['simulator']
    assert sorted(labels) == sorted(n.label for n in system.nodes)
    for group in members.values():
        for label in group:   # each composed node's executable is composable
            spec = next(n for n in system.nodes if n.label == label)
            assert node_class(spec.package, spec.executable).__name__


def test_node_class_finds_the_one_node_class_of_an_executable():
    assert node_class('mecanum_navigation', 'navigator').__name__ == 'NavigatorNode'
    assert node_class('mecanum_control', 'hardware_interface').__name__ == 'HardwareInterface'


@pytest.mark.parametrize('package, executable, message', [
    ('no_such_package', 'x', "package 'no_such_package' is not installed"),
    ('mecanum_navigation', 'no_such_exec', "has no executable 'no_such_exec'"),
    ('robot_simulation', 'simulator_node', 'cannot run in a container'),
])
def test_node_class_explains_what_cannot_be_composed(package, executable, message):
    with pytest.raises(CompositionError, match=message):
        node_class(package, executable)


@pytest.mark.parametrize('text, message', [
    ('not json', 'not JSON'),
    ('[]', 'non-empty JSON list'),
    ('[3]', 'node 0: expected an object'),
    ('[{"label": "a", "package": "p"}]', "node 0: 'executable' must be"),
    ('[{"label": "a", "package": "p", "executable": "e", "ros_args": [1]}]',
     'node a: ros_args must be a list of strings'),
])
def test_parse_spec_rejects_bad_node_lists(text, message):
    with pytest.raises(CompositionError, match=message):
        parse_spec(text)
