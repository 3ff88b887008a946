"""Tests of world_to_map and of the maps in mecanum_navigation/maps made from the worlds."""

from pathlib import Path

from mecanum_map_server.map_io import find_map_file, load_map
import numpy as np
from robot_simulation.world import find_world, load_world
from robot_simulation.world_to_map import main

SOURCE_MAPS = Path(__file__).resolve().parents[2] / 'mecanum_map_server' / 'maps'


def test_the_committed_apartment_map_is_the_apartment_world(tmp_path):
    """maps/apartment.* must be what world_to_map makes now (rerun it after editing the world)."""
    assert main(['apartment', str(tmp_path / 'apartment.yaml')]) == 0
    for name in ('apartment.yaml', 'apartment.pgm'):
        assert (tmp_path / name).read_bytes() == (SOURCE_MAPS / name).read_bytes(), (
            f'{name} is out of date: run ./mecanum run robot_simulation world_to_map '
            'apartment src/mecanum_map_server/maps/apartment.yaml')


def test_the_map_marks_walls_and_leaves_rooms_free():
    occupancy = load_map(find_map_file('apartment'))
    world = load_world(find_world('apartment'))
    assert occupancy.origin == (world.bounds[0], world.bounds[1], 0.0)

    def cell(x, y):
        row = int((y - occupancy.origin[1]) / occupancy.resolution_m)
        col = int((x - occupancy.origin[0]) / occupancy.resolution_m)
        return occupancy.data[row, col]
    assert cell(6.0, 2.0) == 100   # the living room's east wall (centre line x = 6.0)
    assert cell(2.95, 2.0) == 0    # the robot's start in the living room
    assert cell(1.5, 4.0) == 0     # the living room <-> hallway doorway
    assert set(np.unique(occupancy.data)) <= {0, 100}


def test_the_lab_world_reads_its_map_from_the_navigation_package():
    world = load_world(find_world('lab'))
    lab_map = load_map(find_map_file('package://mecanum_map_server/maps/lab_map.yaml'))
    assert world.occupancy is not None
    assert np.array_equal(world.occupancy.data, lab_map.data)


def test_bad_input_gives_exit_code_2(tmp_path, capsys):
    assert main(['moon', str(tmp_path / 'x.yaml')]) == 2
    assert "unknown world 'moon'" in capsys.readouterr().err
    assert main(['apartment', str(tmp_path / 'x.yaml'), '--resolution', '0']) == 2
