"""
Integration: map_server publishes a Nav2 map on /map; map_saver_cli writes it back.

Real processes in the test's own ROS domain; the round trip through DDS and the files
must be lossless in every mode (trinary, scale and raw maps come back the same).
"""

from pathlib import Path
import re
import subprocess
import time

from mecanum_navigation.map_io import find_map_file, load_map, OccupancyMap, save_map
from nav_msgs.msg import OccupancyGrid
import numpy as np
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize('map_name', ['apartment', 'lab_map'])
def test_map_round_trip_through_server_and_saver(start_system, test_node, ros_env, tmp_path,
                                                 map_name):
    original = load_map(find_map_file(map_name))
    system = start_system('mecanum_navigation', 'map_server.launch.yaml', f'map:={map_name}')
    system.wait_for_line(r'\[map_server\].*Serving map')
    maps = []
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    test_node.node.create_subscription(OccupancyGrid, 'map', maps.append, latched)
    saved = tmp_path / 'saved'
    result = subprocess.run(
        ['./mecanum', 'run', 'mecanum_navigation', 'map_saver_cli', '-f', str(saved)],
        env=ros_env, capture_output=True, text=True, timeout=60, cwd=str(REPO))
    assert result.returncode == 0, result.stdout + result.stderr
    deadline = time.monotonic() + 10.0
    while not maps and time.monotonic() < deadline:
        time.sleep(0.05)
    assert maps, 'no latched map reached the test node'
    msg = maps[0]
    assert msg.header.frame_id == 'map'
    assert (msg.info.width, msg.info.height) == (original.width, original.height)
    assert msg.info.resolution == pytest.approx(original.resolution_m)
    assert msg.info.origin.position.x == pytest.approx(original.origin[0])
    assert np.array_equal(np.array(msg.data, dtype=np.int8).reshape(original.data.shape),
                          original.data)
    again = load_map(saved.with_suffix('.yaml'))
    assert np.array_equal(again.data, original.data)
    assert again.origin == pytest.approx(original.origin)


@pytest.mark.parametrize('mode', ['scale', 'raw'])
def test_scale_and_raw_maps_round_trip_through_server_and_saver(start_system, ros_env,
                                                                tmp_path, mode):
    """A map of every value the mode holds: file -> map_server -> DDS -> map_saver_cli."""
    values = np.arange(101) if mode == 'scale' else np.arange(-1, 101)
    data = np.resize(values, (40, 61)).astype(np.int8)
    original = OccupancyMap(0.05, (-1.0, 0.5, 0.0), data)
    save_map(original, tmp_path / 'source.yaml', mode=mode)
    system = start_system('mecanum_navigation', 'map_server.launch.yaml',
                          f'map:={tmp_path / "source.yaml"}')
    system.wait_for_line(r'\[map_server\].*Serving map')
    saved = tmp_path / 'saved'
    result = subprocess.run(
        ['./mecanum', 'run', 'mecanum_navigation', 'map_saver_cli', '-f', str(saved),
         '--mode', mode],
        env=ros_env, capture_output=True, text=True, timeout=60, cwd=str(REPO))
    assert result.returncode == 0, result.stdout + result.stderr
    again = load_map(saved.with_suffix('.yaml'))
    assert np.array_equal(again.data, original.data)
    assert (tmp_path / 'saved.pgm').read_bytes() == (tmp_path / 'source.pgm').read_bytes()


def test_a_missing_map_stops_the_server_with_a_clear_message(ros_env):
    result = subprocess.run(
        ['./mecanum', 'run', 'mecanum_navigation', 'map_server', '--ros-args', '-p',
         'yaml_filename:=/nonexistent/house.yaml'],
        env=ros_env, capture_output=True, text=True, timeout=60, cwd=str(REPO))
    output = result.stdout + result.stderr
    assert result.returncode == 2, output
    assert 'Traceback' not in output
    assert re.search(r'\[FATAL\].*cannot load map.*no map file at /nonexistent/house.yaml',
                     output), output


def test_saver_without_a_map_gives_up_with_an_error(ros_env, tmp_path):
    result = subprocess.run(
        ['./mecanum', 'run', 'mecanum_navigation', 'map_saver_cli', '-f',
         str(tmp_path / 'none'), '--timeout', '1'],
        env=ros_env, capture_output=True, text=True, timeout=60, cwd=str(REPO))
    assert result.returncode == 1
    assert 'No map received' in result.stdout + result.stderr
    assert not (tmp_path / 'none.yaml').exists()
