from setuptools import find_packages, setup

package_name = 'ros2bag_mcap'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml', 'README.md']),
    ],
    install_requires=['ros2cli'],
    zip_safe=True,
    maintainer='mecanum_robot maintainers',
    maintainer_email='maintainers@mecanum-robot.dev',
    description=(
        'The bag command (info, play, record) of the ros2 command line tools for MCAP bags, '
        'in Python, for the pip setup where rosbag2 (C++) cannot be built'),
    license='Apache-2.0',
    extras_require={'test': ['pytest']},
    entry_points={
        'ros2cli.command': [
            'bag = ros2bag_mcap.command.bag:BagCommand',
        ],
        'ros2cli.extension_point': [
            'ros2bag_mcap.verb = ros2bag_mcap.verb:VerbExtension',
        ],
        'ros2bag_mcap.verb': [
            'info = ros2bag_mcap.verb.info:InfoVerb',
            'play = ros2bag_mcap.verb.play:PlayVerb',
            'record = ros2bag_mcap.verb.record:RecordVerb',
        ],
    },
)
