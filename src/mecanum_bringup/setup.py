from glob import glob
import os

from setuptools import find_packages, setup

package_name = 'mecanum_bringup'


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
    ] + share('launch/*.launch.py', 'launch/*.launch.yaml', 'config/**/*.yaml',
              'config/*.xml', 'scenarios/*.yaml', 'sweeps/*.yaml'),
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='mecanum_robot maintainers',
    maintainer_email='maintainers@mecanum-robot.dev',
    description=(
        'Bringup of the mecanum robot'),
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'launch_runner = mecanum_bringup.launch_runner:main',
            'bag_recorder = mecanum_bringup.bag_recorder:main',
            'foxglove_bridge = mecanum_bringup.foxglove_bridge:main',
            'run_scenarios = mecanum_bringup.scenario_runner:main',
            'run_sweep = mecanum_bringup.sweep_runner:main',
            'compare_sweeps = mecanum_bringup.sweep_runner:compare_main',
            'demo = mecanum_bringup.demo:main',
            'node_container = mecanum_bringup.node_container:main',
        ],
    },
)
