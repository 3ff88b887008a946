from glob import glob
import os

from setuptools import find_packages, setup

package_name = 'robot_controller'


def share(*patterns):
    """Return the data_files entries installing files that match patterns under share/."""
    entries = {}
    for pattern in patterns:
        for path in glob(pattern, recursive=True):
            if os.path.isfile(path):
                target = os.path.join('share', package_name, os.path.dirname(path))
                entries.setdefault(target, []).append(path)
    return sorted(entries.items())


setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml', 'README.md']),
    ] + share('launch/*.launch.py', 'launch/*.launch.yaml', 'config/**/*.yaml'),
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='mecanum_robot maintainers',
    maintainer_email='maintainers@mecanum-robot.dev',
    description=(
        'Text commands ("forward 0.5 m", "strafe left 2 s") to velocity commands on cmd_vel'),
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'robot_control_node = robot_controller.robot_control_node:main',
            'command_script = robot_controller.command_script:main',
        ],
    },
)
