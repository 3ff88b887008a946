from glob import glob
import os

from setuptools import find_packages, setup

package_name = 'mecanum_map_server'


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
    ] + share('launch/*.launch.py', 'launch/*.launch.yaml', 'maps/*'),
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='mecanum_robot maintainers',
    maintainer_email='maintainers@mecanum-robot.dev',
    description=(
        'Maps of the mecanum robot: map server and saver, the map file format'),
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'map_server = mecanum_map_server.map_server:main',
            'map_saver_cli = mecanum_map_server.map_saver:main',
            'map_saver_server = mecanum_map_server.map_saver_server:main',
        ],
    },
)
