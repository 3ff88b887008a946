"""
map_saver_server: nav2_map_server's map saver server for the pip setup (node map_saver).

Service ``~/save_map`` (nav2_msgs/SaveMap, as Nav2's: ``/map_saver/save_map``): takes one
nav_msgs/OccupancyGrid from ``map_topic`` ('' = 'map'; transient local, so a map
server's or SLAM's latched map arrives at once) and writes it as a Nav2 map at
``map_url`` (a path without extension, ``file://`` allowed; '' = 'map'), ``NAME.yaml``
+ ``NAME.pgm`` (mecanum_map_server.map_io.save_map), in ``map_mode`` ('' = trinary,
scale, raw) with ``free_thresh`` / ``occupied_thresh`` (0 = the defaults below).
``image_format`` must be '' or 'pgm' (only PGM is written here). The response's
``result`` is true once written; every refusal or failure is logged with its reason.

Parameters: ``save_map_timeout`` (2.0 s: how long to wait for the map),
``free_thresh_default`` (map_io's 0.196, so the unknown grey loads back as unknown),
``occupied_thresh_default`` (0.65).
"""

from pathlib import Path
import sys

from mecanum_control.node_main import run_node
from mecanum_control.parameters import declare_number, positive
from mecanum_control.runtime_parameters import read_only_parameters
from mecanum_map_server.map_io import MapError, MODES, SAVE_FREE_THRESH, SAVE_OCCUPIED_THRESH
from mecanum_map_server.map_saver import take_latched_map, write_map
from nav2_msgs.srv import SaveMap
import rclpy
from rclpy.node import Node


class MapSaverServer(Node):
    """Saves the map of a topic on request."""

    def __init__(self):
        super().__init__('map_saver')
        self.timeout_s = positive('save_map_timeout',
                                  declare_number(self, 'save_map_timeout', 2.0))
        self.free_default = declare_number(self, 'free_thresh_default', SAVE_FREE_THRESH)
        self.occupied_default = declare_number(self, 'occupied_thresh_default',
                                               SAVE_OCCUPIED_THRESH)
        if not 0.0 <= self.free_default < self.occupied_default <= 1.0:
            raise ValueError('parameters need 0 <= free_thresh_default < '
                             'occupied_thresh_default <= 1')
        self.service = self.create_service(SaveMap, '~/save_map', self.on_save_map)
        self.get_logger().info(
            f'Map saver ready on {self.resolve_service_name(self.service.srv_name)}')
        read_only_parameters(self)

    def on_save_map(self, request, response):
        """Save one map of request.map_topic to request.map_url (nav2_msgs/SaveMap)."""
        response.result = False
        mode = request.map_mode or 'trinary'
        free = request.free_thresh or self.free_default
        occupied = request.occupied_thresh or self.occupied_default
        url = request.map_url.strip() or 'map'
        if url.startswith('file://'):
            url = url[len('file://'):]
        problem = ''
        if request.image_format not in ('', 'pgm'):
            problem = f'image_format {request.image_format!r}: only pgm is written here'
        elif mode not in MODES:
            problem = f'map_mode {mode!r}: expected one of {", ".join(MODES)}'
        elif not 0.0 <= free < occupied <= 1.0:
            problem = f'thresholds: need 0 <= free_thresh ({free}) < occupied_thresh ' \
                      f'({occupied}) <= 1'
        if problem:
            self.get_logger().error(f'save_map refused: {problem}')
            return response
        topic = request.map_topic or 'map'
        msg = self._take_map(topic)
        if msg is None:
            self.get_logger().error(f'save_map: no map on {topic} within {self.timeout_s:g} s')
            return response
        yaml_path = Path(url).expanduser().with_suffix('.yaml')
        try:
            write_map(msg, yaml_path, mode, occupied, free, self.get_logger())
        except (MapError, OSError, ValueError) as error:
            self.get_logger().error(f'save_map: could not save the map: {error}')
            return response
        self.get_logger().info(f'Map of {topic} saved to {yaml_path} and '
                               f'{yaml_path.with_suffix(".pgm")}')
        response.result = True
        return response

    def _take_map(self, topic: str):
        """
        Return one map from topic, or None after save_map_timeout.

        Through a node of its own: this service callback runs in the node's executor,
        which cannot deliver the map meanwhile.
        """
        helper = rclpy.create_node('map_saver_listener', context=self.context,
                                   start_parameter_services=False)
        try:
            return take_latched_map(helper, topic, self.timeout_s)
        finally:
            helper.destroy_node()


def main(args=None) -> int:
    """Run the map saver server until Ctrl-C or SIGTERM."""
    return run_node(MapSaverServer, 'map_saver', args)


if __name__ == '__main__':
    sys.exit(main())
