"""
map_saver_cli: nav2_map_server's map saver for the pip setup.

Waits for one nav_msgs/OccupancyGrid on ``--map-topic`` ('map'; transient local, so a
map server's or SLAM's latched map arrives at once) and writes it as a Nav2 map,
``NAME.yaml`` + ``NAME.pgm`` (``mecanum_map_server.map_io.save_map``, trinary by
default, as map_saver writes it). Usage, as Nav2's::

    map_saver_cli -f ~/maps/apartment [-t map] [--mode trinary|scale|raw] [--occ 0.65]
                  [--free 0.196] [--timeout 10]

In scale mode unknown cells cannot be stored in a PGM; they are written as map_saver's
grey 205 with a warning.

The default free threshold is map_io's 0.196 rather than Nav2's 0.25, so that the
unknown grey it writes loads back as unknown (see map_io).

Exit code 0 once saved, 1 when no map arrived in time or it could not be written.
"""

import argparse
from pathlib import Path
import sys
import time
from typing import Optional

from mecanum_map_server.grid_messages import occupancy_map
from mecanum_map_server.map_io import (
    MapError, MODES, SAVE_FREE_THRESH, save_map, SAVE_OCCUPIED_THRESH)
from nav_msgs.msg import OccupancyGrid
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile


def take_latched_map(node: Node, topic: str, timeout_s: float) -> Optional[OccupancyGrid]:
    """
    Return one map from topic (transient local), or None after timeout_s.

    Spins node alone, on an executor of its own (map_saver_server calls it from a service
    callback, where the node's own executor is busy), then drops the subscription.
    """
    received = []
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    subscription = node.create_subscription(OccupancyGrid, topic, received.append, latched)
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    deadline = time.monotonic() + timeout_s
    try:
        while not received and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
    finally:
        executor.shutdown()
        node.destroy_subscription(subscription)
    return received[-1] if received else None


def write_map(msg: OccupancyGrid, yaml_path: Path, mode: str, occupied_thresh: float,
              free_thresh: float, logger) -> None:
    """
    Write a received map as a Nav2 map (YAML + PGM) with map_io.save_map.

    In scale mode unknown cells are written as grey 205, with a warning. Raises
    MapError, OSError or ValueError when it cannot be written.
    """
    grid = occupancy_map(msg)
    unknown = int((grid.data < 0).sum())
    if mode == 'scale' and unknown:
        logger.warning(f'{unknown} unknown cell(s) are written as grey 205 and load back '
                       'as a scale value (a PGM has no alpha channel)')
    save_map(grid, yaml_path, occupied_thresh=occupied_thresh, free_thresh=free_thresh,
             mode=mode, allow_unknown_loss=True)


def main(args=None) -> int:
    """Save one map from the map topic; return the exit code."""
    argv = rclpy.utilities.remove_ros_args(sys.argv if args is None else args)[1:]
    parser = argparse.ArgumentParser(prog='map_saver_cli', description=__doc__.splitlines()[1])
    parser.add_argument('-f', dest='name', default='map',
                        help='map file name without extension (default: map)')
    parser.add_argument('-t', '--map-topic', default='map', help='topic of the map (map)')
    parser.add_argument('--occ', type=float, default=SAVE_OCCUPIED_THRESH,
                        help=f'occupied threshold, 0..1 ({SAVE_OCCUPIED_THRESH})')
    parser.add_argument('--free', type=float, default=SAVE_FREE_THRESH,
                        help=f'free threshold, 0..1 ({SAVE_FREE_THRESH})')
    parser.add_argument('--mode', choices=MODES, default='trinary',
                        help='map mode: trinary (default), scale or raw')
    parser.add_argument('--timeout', type=float, default=10.0,
                        help='seconds to wait for a map (10)')
    options = parser.parse_args(argv)
    if not 0.0 <= options.free < options.occ <= 1.0:
        parser.error('need 0 <= --free < --occ <= 1')
    rclpy.init(args=args)
    node = rclpy.create_node('map_saver')
    received = None
    try:
        received = take_latched_map(node, options.map_topic, options.timeout)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    logger = rclpy.logging.get_logger('map_saver')
    if received is None:
        logger.error(f'No map received on {options.map_topic} within {options.timeout:g} s')
        return 1
    yaml_path = Path(options.name).expanduser().with_suffix('.yaml')
    try:
        write_map(received, yaml_path, options.mode, options.occ, options.free, logger)
    except (MapError, OSError, ValueError) as error:
        logger.error(f'Could not save the map: {error}')
        return 1
    logger.info(f'Map saved to {yaml_path} and {yaml_path.with_suffix(".pgm")}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
