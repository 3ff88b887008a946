"""
nav_msgs/OccupancyGrid <-> map_io.OccupancyMap (the ROS side of the map files).

Both keep ROS's cell order (row 0 is the lowest y), so the data is copied as is. The
origin's yaw becomes a rotation about z of the info.origin pose.
"""

from builtin_interfaces.msg import Time
from mecanum_control.angles import quaternion_from_yaw, yaw_from_quaternion
from mecanum_map_server.map_io import OccupancyMap
from nav_msgs.msg import OccupancyGrid
import numpy as np


def occupancy_grid(occupancy_map: OccupancyMap, frame_id: str, stamp: Time) -> OccupancyGrid:
    """Return the OccupancyGrid message of a map (cells -1 or 0..100)."""
    msg = OccupancyGrid()
    msg.header.frame_id = frame_id
    msg.header.stamp = stamp
    msg.info.map_load_time = stamp
    msg.info.resolution = float(occupancy_map.resolution_m)
    msg.info.width = occupancy_map.width
    msg.info.height = occupancy_map.height
    x, y, yaw = occupancy_map.origin
    msg.info.origin.position.x = float(x)
    msg.info.origin.position.y = float(y)
    q = msg.info.origin.orientation
    q.x, q.y, q.z, q.w = quaternion_from_yaw(yaw)
    msg.data = occupancy_map.data.reshape(-1).astype(np.int8).tolist()
    return msg


def occupancy_map(msg: OccupancyGrid) -> OccupancyMap:
    """Return the map of an OccupancyGrid message; ValueError if it is inconsistent."""
    width, height = int(msg.info.width), int(msg.info.height)
    if width * height != len(msg.data) or width < 1 or height < 1:
        raise ValueError(f'OccupancyGrid of {width} x {height} cells has {len(msg.data)} '
                         'values')
    q = msg.info.origin.orientation
    yaw = yaw_from_quaternion(q.x, q.y, q.z, q.w)
    data = np.asarray(msg.data, dtype=np.int8).reshape(height, width)
    return OccupancyMap(float(msg.info.resolution),
                        (msg.info.origin.position.x, msg.info.origin.position.y, yaw), data)
