"""Launch the collision monitor with ros2 launch; the system is collision_monitor.launch.yaml."""

import os

from launch import LaunchDescription
from launch.actions import IncludeLaunchDescription
from launch.launch_description_sources import AnyLaunchDescriptionSource


def generate_launch_description():
    """Include the YAML system description that the pip-setup runner also reads."""
    here = os.path.dirname(os.path.realpath(__file__))
    return LaunchDescription([IncludeLaunchDescription(
        AnyLaunchDescriptionSource(os.path.join(here, 'collision_monitor.launch.yaml')))])
