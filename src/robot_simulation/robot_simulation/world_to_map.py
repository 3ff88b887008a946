"""
world_to_map: save a simulator world as a Nav2 map (YAML + PGM), as a perfect SLAM run would.

Usage::

    world_to_map apartment maps/apartment.yaml [--resolution 0.05]

The world (an installed world's name or a world file) is rasterised by
``World.to_occupancy_map`` (walls, furniture and circles occupied, the rest free or as
its own map says; moving obstacles left out) and written by
``mecanum_map_server.map_io.save_map`` (trinary, as map_saver writes). This is how
``mecanum_map_server/maps/apartment.yaml`` is made; a test checks it is up to date.
"""

import argparse
from pathlib import Path
import sys
from typing import List, Optional

from mecanum_map_server.map_io import MapError, save_map
from robot_simulation.world import find_world, load_world, WorldError


def main(argv: Optional[List[str]] = None) -> int:
    """Write the map of a world; return the exit code (2 on bad input)."""
    parser = argparse.ArgumentParser(prog='world_to_map', description=__doc__.splitlines()[1])
    parser.add_argument('world', help='an installed world (apartment, lab) or a world file')
    parser.add_argument('output', type=Path, help='the map YAML to write (PGM beside it)')
    parser.add_argument('--resolution', type=float, default=0.05,
                        help='cell size in metres (0.05)')
    options = parser.parse_args(argv)
    try:
        world = load_world(find_world(options.world))
        image = save_map(world.to_occupancy_map(options.resolution), options.output)
    except (WorldError, MapError, ValueError, OSError) as error:
        print(f'world_to_map: {error}', file=sys.stderr)
        return 2
    print(f'wrote {options.output} and {image}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
