"""The workspace is a proper colcon workspace that an apt ROS 2 install can build."""

import ast
import os
from pathlib import Path
import subprocess
import sys
from xml.etree import ElementTree

from catkin_pkg.package import parse_package
from mecanum_bringup.launch_runner import find_executable
from mecanum_bringup.system_description import load_system
import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]
PACKAGES = sorted(p.parent.name for p in (REPO / 'src').glob('*/package.xml'))
PYTHON_PACKAGES = [p for p in PACKAGES if (REPO / 'src' / p / 'setup.py').exists()]
LAUNCH_FILES = sorted((REPO / 'src').glob('*/launch/*.launch.yaml'))


def test_the_seed_packages_exist():
    assert set(PACKAGES) == {
        'mecanum_description', 'mecanum_control', 'mecanum_localization',
        'mecanum_navigation', 'mecanum_bringup', 'robot_controller', 'robot_simulation',
        'mecanum_safety', 'mecanum_map_server',
        'mecanum_interfaces'}


@pytest.mark.parametrize('package', PACKAGES)
def test_package_xml_is_valid_format_3(package):
    manifest = parse_package(REPO / 'src' / package / 'package.xml')  # validates
    assert manifest.name == package
    assert manifest.package_format == 3
    manifest.validate()


@pytest.mark.parametrize('package', PYTHON_PACKAGES)
def test_ament_python_package_has_the_standard_files(package):
    root = REPO / 'src' / package
    for name in ('setup.py', 'setup.cfg', f'resource/{package}', 'README.md',
                 'test/test_flake8.py', 'test/test_pep257.py', f'{package}/__init__.py'):
        assert (root / name).exists(), f'{package} lacks {name}'
    assert f'script_dir=$base/lib/{package}' in (root / 'setup.cfg').read_text()


def test_apt_users_colcon_sees_only_the_workspace_packages():
    """Run at the repository root, colcon must not find the venv or the pip-only overlay."""
    listed = subprocess.run(['colcon', 'list', '--names-only', '--base-paths', str(REPO)],
                            cwd=REPO, capture_output=True, text=True, check=True)
    assert sorted(listed.stdout.split()) == PACKAGES


@pytest.mark.parametrize('launch_file', LAUNCH_FILES, ids=lambda p: f'{p.parent.parent.name}/'
                         f'{p.name}')
def test_every_system_description_resolves(launch_file):
    """Every launch YAML loads, its packages, executables and parameter files exist."""
    system = load_system(launch_file)
    for node in system.nodes:
        assert find_executable(node.package, node.executable, os.environ).is_file()
    wrapper = launch_file.with_name(launch_file.name.replace('.launch.yaml', '.launch.py'))
    assert wrapper.exists() and launch_file.name in wrapper.read_text()


@pytest.mark.parametrize('arguments, expected', [
    ({}, {'simulator', 'map_server', 'amcl', 'navigator'}),
    ({'slam': 'true'}, {'simulator', 'slam_toolbox', 'navigator'}),
    ({'sim': 'false'}, {'hardware_interface', 'map_server', 'amcl', 'navigator'}),
])
def test_robot_launch_chooses_robot_and_localisation(arguments, expected):
    """robot.launch.yaml: simulated or real robot, amcl on a map or SLAM, navigation."""
    system = load_system(REPO / 'src/mecanum_bringup/launch/robot.launch.yaml', arguments)
    labels = [node.label for node in system.nodes]
    assert len(labels) == len(set(labels)), labels  # one map source, one of each node
    assert expected <= set(labels)
    for absent in {'simulator', 'map_server', 'amcl', 'slam_toolbox'} - expected:
        assert absent not in labels
    assert {'ekf_filter_node', 'robot_state_publisher', 'velocity_smoother',
            'collision_monitor', 'motor_controller'} <= set(labels)


def _zone_guard_parameter(system, name):
    """Return the last override of parameter name given to the zone_guard node."""
    guards = [node for node in system.nodes if node.label == 'zone_guard']
    assert len(guards) == 1, [node.label for node in system.nodes]
    values = [value for item in guards[0].parameters if isinstance(item, tuple)
              for key, value in [item] if key == name]
    return values[-1] if values else None


@pytest.mark.parametrize('arguments, topic', [
    ({}, 'amcl_pose'),
    ({'slam': 'true'}, 'pose'),
    ({'sim': 'false'}, 'amcl_pose'),
    ({'sim': 'false', 'slam': 'true'}, 'pose'),
])
def test_the_zone_guard_hears_the_localisation_in_use(arguments, topic):
    """The guard hears amcl_pose from amcl, pose from SLAM (slam_toolbox): margin, health."""
    system = load_system(REPO / 'src/mecanum_bringup/launch/robot.launch.yaml', arguments)
    assert _zone_guard_parameter(system, 'pose_covariance_topic') == topic


@pytest.mark.parametrize('launch_file, arguments, required', [
    ('mecanum_bringup/launch/real_robot.launch.yaml', {}, True),
    ('mecanum_bringup/launch/robot.launch.yaml', {'sim': 'false'}, True),
    ('mecanum_bringup/launch/robot.launch.yaml', {}, False),
    ('mecanum_bringup/launch/simulation.launch.yaml', {}, False),
    ('mecanum_safety/launch/command_chain.launch.yaml', {}, False),
])
def test_the_real_robot_does_not_drive_without_a_zone_file(launch_file, arguments, required):
    """With zone_file '' the real robot's zone guard stops every command; the simulation's not."""
    system = load_system(REPO / 'src' / launch_file, arguments)
    assert _zone_guard_parameter(system, 'zone_file') == ''
    assert _zone_guard_parameter(system, 'require_zone') is required


def test_the_zone_guard_file_leaves_the_launch_parameters_to_the_launch_files():
    """
    zone_guard.yaml sets none of the parameters command_chain.launch.yaml gives.

    A launch override ({name, value}) goes under /** in the pip setup, which rclpy reads
    before the node's own section: zone_guard.yaml setting one would silently win.
    """
    params = yaml.safe_load((REPO / 'src/mecanum_safety/config/zone_guard.yaml').read_text())
    system = load_system(REPO / 'src/mecanum_safety/launch/command_chain.launch.yaml')
    given = {item[0] for node in system.nodes if node.label == 'zone_guard'
             for item in node.parameters if isinstance(item, tuple)}
    assert {'zone_file', 'require_zone', 'pose_covariance_topic'} <= given
    assert not given & set(params['zone_guard']['ros__parameters'])


def test_zone_file_unrestricted_reaches_every_reader_of_the_zone():
    """zone_file:=unrestricted is how the real robot drives without a zone, on purpose."""
    system = load_system(REPO / 'src/mecanum_bringup/launch/robot.launch.yaml',
                         {'sim': 'false', 'zone_file': 'unrestricted'})
    readers = [node for node in system.nodes
               if any(isinstance(item, tuple) and item[0] == 'zone_file'
                      for item in node.parameters)]
    assert {node.label for node in readers} == {'zone_guard', 'navigator', 'robot_controller'}
    for node in readers:
        assert [value for key, value in (item for item in node.parameters
                                         if isinstance(item, tuple))
                if key == 'zone_file'][-1] == 'unrestricted'


def test_installed_executables_run_directly():
    """./mecanum run is the pip setup's `ros2 run`: it finds and starts the executable."""
    result = subprocess.run(
        [str(REPO / 'mecanum'), 'run', 'robot_controller', 'command_script', '--ros-args',
         '-p', 'start_delay_s:=0.5'],
        capture_output=True, text=True, timeout=60)
    # No "commands" parameter given: the node itself refuses to start, with a clear error.
    assert result.returncode == 2
    assert 'parameter "commands" must list at least one command' in result.stderr
    missing = subprocess.run([str(REPO / 'mecanum'), 'run', 'robot_controller', 'nope'],
                             capture_output=True, text=True, timeout=60)
    assert missing.returncode == 2 and "No executable 'nope'" in missing.stderr


# The house: each workspace package imports only packages of the floors below it, so
# the dependency graph has no cycle and no arrow back up (the chain and the maps below
# navigation, navigation below the simulator's and the robot's launch).
FLOORS = [
    ['mecanum_interfaces'],
    ['mecanum_control'],
    ['mecanum_description', 'mecanum_localization'],
    ['mecanum_map_server', 'mecanum_safety'],
    ['mecanum_navigation', 'robot_controller', 'robot_simulation'],
    ['mecanum_bringup'],
]
# Inside mecanum_navigation, by Nav2's concerns: each subpackage imports only earlier ones.
NAVIGATION_FLOORS = ['costmap', 'planner', 'controller', 'amcl', 'slam', 'navigator']


def workspace_imports(folder: Path, names) -> dict:
    """Return {imported dotted module: [file:line, ...]} of folder's .py files within names."""
    found = {}
    for path in sorted(folder.rglob('*.py')):
        tree = ast.parse(path.read_text(encoding='utf-8'), str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                modules = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                modules = [node.module] + [f'{node.module}.{a.name}' for a in node.names]
            else:
                continue
            for module in modules:
                if module.split('.')[0] in names:
                    found.setdefault(module, []).append(
                        f'{path.relative_to(REPO)}:{node.lineno}')
    return found


def test_the_floors_name_every_package_once():
    listed = [package for floor in FLOORS for package in floor]
    assert sorted(listed) == PACKAGES


@pytest.mark.parametrize('package', PYTHON_PACKAGES)
def test_a_package_imports_only_floors_below_it_and_declares_them(package):
    """No arrow back up, none across a floor (but in tests), each one in package.xml."""
    floor_of = {p: i for i, floor in enumerate(FLOORS) for p in floor}
    manifest = parse_package(REPO / 'src' / package / 'package.xml')
    declared = {d.name for d in manifest.exec_depends + manifest.test_depends}
    wrong = []
    for folder, allowed in ((REPO / 'src' / package / package, 'exec'),
                            (REPO / 'src' / package / 'test', 'test')):
        for module, places in workspace_imports(folder, floor_of).items():
            target = module.split('.')[0]
            if target == package:
                continue
            # Tests may also use a package beside theirs (the simulator's lidar model),
            # never one above.
            above = floor_of[target] > floor_of[package] if allowed == 'test' else (
                floor_of[target] >= floor_of[package])
            if above:
                wrong.append(f'{places[0]} imports {module} (floor {floor_of[target]}, '
                             f'{package} is on floor {floor_of[package]})')
            elif target not in declared:
                wrong.append(f'{places[0]} imports {module}, not in package.xml')
    assert not wrong, '\n'.join(wrong)


def test_navigation_subpackages_import_only_earlier_concerns():
    root = REPO / 'src/mecanum_navigation/mecanum_navigation'
    assert sorted(p.name for p in root.iterdir() if (p / '__init__.py').exists()) == sorted(
        NAVIGATION_FLOORS)
    assert sorted(p.name for p in root.glob('*.py')) == ['__init__.py']
    wrong = []
    for index, concern in enumerate(NAVIGATION_FLOORS):
        imports = workspace_imports(root / concern, {'mecanum_navigation'})
        for module, places in imports.items():
            parts = module.split('.')
            if len(parts) < 2 or parts[1] == concern:
                continue
            if parts[1] not in NAVIGATION_FLOORS[:index]:
                wrong.append(f'{places[0]} ({concern}) imports {module}')
    assert not wrong, '\n'.join(wrong)


@pytest.mark.parametrize('package', ['robot_controller', 'robot_simulation', 'mecanum_safety',
                                     'mecanum_map_server'])
def test_the_zone_and_the_maps_are_read_without_navigation(package):
    """The chain, robot_controller and the simulator read zones and maps, not navigation."""
    root = REPO / 'src' / package
    imports = workspace_imports(root, {'mecanum_navigation'})
    assert not imports, imports
    manifest = parse_package(root / 'package.xml')
    assert 'mecanum_navigation' not in {d.name for d in manifest.exec_depends}


@pytest.mark.parametrize('launch_file', LAUNCH_FILES, ids=lambda p: f'{p.parent.parent.name}/'
                         f'{p.name}')
def test_no_launch_parameter_is_shadowed_by_a_node_specific_file_entry(launch_file):
    """
    A launch file's {name, value} for a node must take effect.

    rcl keeps parameter overrides in sections by node name, in the order each section
    first appears on the command line, and a node takes '/**' and its own section in
    that order. A launch {name, value} of a node with no namespace goes to '/**'
    (launch_ros's temp file, or -p here): when a '/**' section came first (a file such
    as motor_params.yaml) and a later file sets the same key under the node's own name,
    the file's value silently wins (checked with rclpy: '-p a:=2' after '/**' then
    'probe: {a: 1}' gives 1).
    """
    system = load_system(launch_file)
    shadowed = []
    for node in system.nodes:
        sections = []         # section names in order of first appearance
        node_keys = {}        # key -> file, set under the node's own name
        for source in node.parameters:
            if isinstance(source, Path):
                document = yaml.safe_load(source.read_text()) or {}
                for key, section in document.items():
                    name = '/**' if key == '/**' else key.lstrip('/')
                    if name not in sections:
                        sections.append(name)
                    if name == node.name and isinstance(section, dict):
                        for parameter in section.get('ros__parameters') or {}:
                            node_keys[parameter] = source
            else:
                if '/**' not in sections:
                    sections.append('/**')
                name = source[0]
                wildcard_first = node.name in sections and sections.index('/**') < sections.index(
                    node.name)
                if wildcard_first and name.split('.')[0] in node_keys:
                    shadowed.append(
                        f'{node.label}: {name} loses to {node_keys[name.split(".")[0]]}')
    assert not shadowed, shadowed


def test_every_process_announces_itself_to_dds_every_half_second(ros_env):
    # tools/env.sh selects the workspace's Fast DDS profile unless the user chose one:
    # a node started into a running system then finds it within 0.5 s, not 3 s
    # (bench/discovery.py). Fast DDS reports a profile it cannot read only as log lines
    # and goes on with its defaults, so the test reads the file and creates a node.
    installed = (REPO / 'install' / 'mecanum_bringup' / 'share' / 'mecanum_bringup'
                 / 'config' / 'fastdds_discovery.xml')
    assert Path(ros_env['FASTRTPS_DEFAULT_PROFILES_FILE']).resolve() == installed.resolve()
    namespace = {'dds': 'http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'}
    root = ElementTree.parse(installed).getroot()
    defaults = [p for p in root.iterfind('dds:profiles/dds:participant', namespace)
                if p.get('is_default_profile') == 'true']
    assert len(defaults) == 1
    discovery = defaults[0].find('dds:rtps/dds:builtin/dds:discovery_config', namespace)
    period = discovery.find('dds:leaseAnnouncement', namespace)
    assert (int(period.find('dds:sec', namespace).text)
            + 1e-9 * int(period.find('dds:nanosec', namespace).text)) == 0.5
    assert discovery.find('dds:leaseDuration', namespace) is None   # 20 s, unchanged
    made = subprocess.run(
        [sys.executable, '-c', 'import rclpy; rclpy.init(); '
         'rclpy.create_node("profile_check").destroy_node(); rclpy.shutdown()'],
        env=ros_env, capture_output=True, text=True, timeout=60)
    assert made.returncode == 0, made.stderr
    assert 'XMLPARSER' not in made.stderr and 'Error' not in made.stderr, made.stderr
