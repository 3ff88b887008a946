"""
map_server: nav2_map_server's map server for the pip setup (node map_server).

Loads a Nav2 map (YAML + PGM, ``mecanum_map_server.map_io``: image, resolution,
origin, negate, occupied_thresh, free_thresh, mode trinary/scale/raw, the same pixel
interpretation as nav2_map_server) and publishes it on ``topic_name`` ('map';
nav_msgs/OccupancyGrid, transient local, so late subscribers get it, as with Nav2) in
``frame_id`` ('map'). Service ``~/map`` (nav_msgs/GetMap) returns it too; service
``~/load_map`` (nav2_msgs/LoadMap, as Nav2's map server) loads another map from
``map_url`` (``file:///path/map.yaml``, ``package://PKG/path`` or what yaml_filename
takes), publishes and returns it: RESULT_MAP_DOES_NOT_EXIST when there is no such file,
RESULT_INVALID_MAP_METADATA for a bad YAML, RESULT_INVALID_MAP_DATA for a bad image; the
map served before stays then. Parameter
``yaml_filename`` (required): a path, a ``package://PKG/path`` in a package's share
directory, or the name of a map in this package's maps/ (``apartment``, ``lab_map``).
A missing or malformed map ends the node with one FATAL line naming the file and the
problem (exit code 2).
"""

import sys

from mecanum_control.node_main import run_node
from mecanum_control.runtime_parameters import read_only_parameters
from mecanum_map_server.grid_messages import occupancy_grid
from mecanum_map_server.map_io import find_map_file, load_map, MapError, MapImageError
from nav2_msgs.srv import LoadMap
from nav_msgs.msg import OccupancyGrid
from nav_msgs.srv import GetMap
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile


class MapServer(Node):
    """Publishes one map, latched, and serves it."""

    def __init__(self, **node_options):
        super().__init__('map_server', **node_options)
        yaml_filename = str(self.declare_parameter('yaml_filename', '').value)
        topic_name = str(self.declare_parameter('topic_name', 'map').value)
        frame_id = str(self.declare_parameter('frame_id', 'map').value)
        if not yaml_filename:
            raise ValueError('parameter yaml_filename is empty: give the map YAML file')
        try:
            path = find_map_file(yaml_filename)
            occupancy = load_map(path)
        except (MapError, LookupError) as error:
            raise ValueError(f'cannot load map: {error}') from None
        self.frame_id = frame_id

        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.map_pub = self.create_publisher(OccupancyGrid, topic_name, latched)
        self.map_srv = self.create_service(GetMap, '~/map', self.on_get_map)
        self.load_srv = self.create_service(LoadMap, '~/load_map', self.on_load_map)
        self._serve(path, occupancy, f' on {self.map_pub.topic_name} in frame {frame_id}')
        read_only_parameters(self)

    def _serve(self, path, occupancy, how: str) -> None:
        """Make occupancy the served map: publish it (latched) and log it, how appended."""
        self.map_msg = occupancy_grid(occupancy, self.frame_id, self.get_clock().now().to_msg())
        self.map_pub.publish(self.map_msg)
        self.get_logger().info(
            f'Serving map {path} ({occupancy.width} x {occupancy.height} cells at '
            f'{occupancy.resolution_m:g} m){how}')

    def on_get_map(self, _request, response):
        """Return the map (nav_msgs/GetMap)."""
        response.map = self.map_msg
        return response

    def on_load_map(self, request, response):
        """Load, publish and return the map at request.map_url (nav2_msgs/LoadMap)."""
        url = request.map_url.strip()
        if url.startswith('file://'):
            url = url[len('file://'):]
        try:
            path = find_map_file(url)
        except (MapError, LookupError) as error:
            self.get_logger().error(f'load_map: {error}')
            response.result = LoadMap.Response.RESULT_MAP_DOES_NOT_EXIST
            return response
        try:
            occupancy = load_map(path)
        except MapError as error:
            self.get_logger().error(f'load_map: {error}; still serving the previous map')
            response.result = (LoadMap.Response.RESULT_INVALID_MAP_DATA
                               if isinstance(error, MapImageError)
                               else LoadMap.Response.RESULT_INVALID_MAP_METADATA)
            return response
        self._serve(path, occupancy, ', loaded on request')
        response.map = self.map_msg
        response.result = LoadMap.Response.RESULT_SUCCESS
        return response


def main(args=None) -> int:
    """Run the map server until Ctrl-C or SIGTERM."""
    return run_node(MapServer, 'map_server', args)


if __name__ == '__main__':
    sys.exit(main())
