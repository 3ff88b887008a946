"""Launch the map server with ros2 launch; the system itself is map_server.launch.yaml."""

import os

from launch import LaunchDescription
from launch.actions import IncludeLaunchDescription
from launch.launch_description_sources import AnyLaunchDescriptionSource


def generate_launch_description():
    """Include the YAML system description that the pip-setup runner also reads."""
    here = os.path.dirname(os.path.realpath(__file__))
    return LaunchDescription([IncludeLaunchDescription(
        AnyLaunchDescriptionSource(os.path.join(here, 'map_server.launch.yaml')))])
