from glob import glob
import os

from setuptools import find_packages, setup

package_name = 'mecanum_safety'


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
    ] + share('launch/*.launch.py', 'launch/*.launch.yaml', 'config/*.yaml', 'zones/*.yaml'),
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='mecanum_robot maintainers',
    maintainer_email='maintainers@mecanum-robot.dev',
    description=(
        'The command chain that guards every motion: twist_mux, collision monitor, zone guard'),
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'collision_monitor = mecanum_safety.collision_monitor_node:main',
            'twist_mux = mecanum_safety.twist_mux_node:main',
            'zone_guard = mecanum_safety.zone_guard_node:main',
        ],
    },
)
