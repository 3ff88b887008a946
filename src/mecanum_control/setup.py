from glob import glob
import os

from setuptools import find_packages, setup

package_name = 'mecanum_control'


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
        ('share/' + package_name + '/doc', glob('doc/*.md')),
    ] + share('launch/*.launch.py', 'launch/*.launch.yaml', 'config/**/*.yaml'),
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='mecanum_robot maintainers',
    maintainer_email='maintainers@mecanum-robot.dev',
    description=(
        'Motor control of the mecanum robot'),
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'console_scripts': [
            'motor_controller = mecanum_control.motor_controller:main',
            'velocity_controller = mecanum_control.velocity_controller:main',
            'encoder_reader = mecanum_control.encoder_reader:main',
            'hardware_interface = mecanum_control.hardware_interface:main',
            'board_emulator = mecanum_control.board_emulator:main',
            'board_check = mecanum_control.board_check:main',
            'teleop_keyboard = mecanum_control.teleop_keyboard:main',
        ],
    },
)
