"""
Integration: map_server publishes a Nav2 map on /map; map_saver_cli writes it back.

map_server's load_map service (nav2_msgs/LoadMap) swaps the map, or says why not;
map_saver_server's save_map (nav2_msgs/SaveMap) writes the served map.

Real processes in the test's own ROS domain; the round trip through DDS and the files
must be lossless in every mode (trinary, scale and raw maps come back the same).
"""

from pathlib import Path
import re
import subprocess
import time

from mecanum_map_server.map_io import find_map_file, load_map, OccupancyMap, save_map
from nav2_msgs.srv import LoadMap, SaveMap
from nav_msgs.msg import OccupancyGrid
import numpy as np
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile
import yaml

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize('map_name', ['apartment', 'lab_map'])
def test_map_round_trip_through_server_and_saver(start_system, test_node, ros_env, tmp_path,
                                                 map_name):
    original = load_map(find_map_file(map_name))
    system = start_system('mecanum_map_server', 'map_server.launch.yaml', f'map:={map_name}')
    system.wait_for_line(r'\[map_server\].*Serving map')
    maps = []
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    test_node.node.create_subscription(OccupancyGrid, 'map', maps.append, latched)
    saved = tmp_path / 'saved'
    result = subprocess.run(
        ['./mecanum', 'run', 'mecanum_map_server', 'map_saver_cli', '-f', str(saved)],
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
    system = start_system('mecanum_map_server', 'map_server.launch.yaml',
                          f'map:={tmp_path / "source.yaml"}')
    system.wait_for_line(r'\[map_server\].*Serving map')
    saved = tmp_path / 'saved'
    result = subprocess.run(
        ['./mecanum', 'run', 'mecanum_map_server', 'map_saver_cli', '-f', str(saved),
         '--mode', mode],
        env=ros_env, capture_output=True, text=True, timeout=60, cwd=str(REPO))
    assert result.returncode == 0, result.stdout + result.stderr
    again = load_map(saved.with_suffix('.yaml'))
    assert np.array_equal(again.data, original.data)
    assert (tmp_path / 'saved.pgm').read_bytes() == (tmp_path / 'source.pgm').read_bytes()


def test_a_missing_map_stops_the_server_with_a_clear_message(ros_env):
    result = subprocess.run(
        ['./mecanum', 'run', 'mecanum_map_server', 'map_server', '--ros-args', '-p',
         'yaml_filename:=/nonexistent/house.yaml'],
        env=ros_env, capture_output=True, text=True, timeout=60, cwd=str(REPO))
    output = result.stdout + result.stderr
    assert result.returncode == 2, output
    assert 'Traceback' not in output
    assert re.search(r'\[FATAL\].*cannot load map.*no map file at /nonexistent/house.yaml',
                     output), output


def test_saver_without_a_map_gives_up_with_an_error(ros_env, tmp_path):
    result = subprocess.run(
        ['./mecanum', 'run', 'mecanum_map_server', 'map_saver_cli', '-f',
         str(tmp_path / 'none'), '--timeout', '1'],
        env=ros_env, capture_output=True, text=True, timeout=60, cwd=str(REPO))
    assert result.returncode == 1
    assert 'No map received' in result.stdout + result.stderr
    assert not (tmp_path / 'none.yaml').exists()


def test_load_map_swaps_the_map_or_says_why_not(start_system, test_node, tmp_path):
    """
    Nav2's load_map serves a good map and refuses bad ones with Nav2's result codes.

    A file:// URL of the lab map: served, published and returned. A missing file, a bad
    YAML and a missing image: their result codes, and the old map stays.
    """
    lab = load_map(find_map_file('lab_map'))
    system = start_system('mecanum_map_server', 'map_server.launch.yaml', 'map:=apartment')
    system.wait_for_line(r'\[map_server\].*Serving map')
    maps = []
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    test_node.node.create_subscription(OccupancyGrid, 'map', maps.append, latched)
    client = test_node.node.create_client(LoadMap, 'map_server/load_map')

    response = test_node.call(client, LoadMap.Request(
        map_url=f'file://{find_map_file("lab_map")}'))
    assert response.result == LoadMap.Response.RESULT_SUCCESS
    assert (response.map.info.width, response.map.info.height) == (lab.width, lab.height)
    assert np.array_equal(np.array(response.map.data, dtype=np.int8).reshape(lab.data.shape),
                          lab.data)
    deadline = time.monotonic() + 10.0
    while not any(m.info.width == lab.width for m in maps) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert any(m.info.width == lab.width for m in maps), 'the new map was not published'

    bad_yaml = tmp_path / 'bad.yaml'
    bad_yaml.write_text('image: x.pgm\nresolution: -1\norigin: [0, 0, 0]\n')
    no_image = tmp_path / 'no_image.yaml'
    no_image.write_text('image: missing.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n'
                        'negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.2\n')
    for url, result in ((str(tmp_path / 'none.yaml'), 'RESULT_MAP_DOES_NOT_EXIST'),
                        (f'file://{bad_yaml}', 'RESULT_INVALID_MAP_METADATA'),
                        (str(no_image), 'RESULT_INVALID_MAP_DATA')):
        response = test_node.call(client, LoadMap.Request(map_url=url))
        assert response.result == getattr(LoadMap.Response, result), url
    system.wait_for_line(r'\[map_server\].*load_map: .*still serving the previous map')
    assert system.stop() == 0


def test_save_map_service_writes_the_served_map(start_system, test_node, tmp_path):
    """
    Nav2's map_saver/save_map writes the latched map; a bad request is refused.

    The lab map round-trips through map_server and the saver server unchanged; a
    request for a PNG image and one for a topic nobody publishes return false.
    """
    lab = load_map(find_map_file('lab_map'))
    launch = tmp_path / 'saver.launch.yaml'
    launch.write_text(yaml.safe_dump({'launch': [
        {'node': {'pkg': 'mecanum_map_server', 'exec': 'map_server', 'name': 'map_server',
                  'param': [{'name': 'yaml_filename', 'value': 'lab_map'}]}},
        {'node': {'pkg': 'mecanum_map_server', 'exec': 'map_saver_server',
                  'name': 'map_saver', 'param': [{'name': 'save_map_timeout', 'value': 1.0}]}},
    ]}))
    system = start_system(str(launch))
    system.wait_for_line(r'\[map_saver\].*Map saver ready on /map_saver/save_map')
    client = test_node.node.create_client(SaveMap, 'map_saver/save_map')
    saved = tmp_path / 'saved'
    response = test_node.call(client, SaveMap.Request(map_url=f'file://{saved}'),
                              timeout=30.0)
    assert response.result is True
    assert np.array_equal(load_map(saved.with_suffix('.yaml')).data, lab.data)
    for request in (SaveMap.Request(map_url=str(tmp_path / 'png'), image_format='png'),
                    SaveMap.Request(map_url=str(tmp_path / 'none'), map_topic='no_map')):
        assert test_node.call(client, request, timeout=30.0).result is False
    system.wait_for_line(r'\[map_saver\].*save_map refused: image_format .png.')
    system.wait_for_line(r'\[map_saver\].*save_map: no map on no_map within 1 s')
    assert not (tmp_path / 'png.yaml').exists() and not (tmp_path / 'none.yaml').exists()
    assert system.stop() == 0
