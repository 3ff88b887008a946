"""The demo program's command line as ros2 launch gives it (demo.launch.yaml)."""

from mecanum_bringup.demo import program_arguments


def test_ros_arguments_and_empty_words_are_dropped():
    assert program_arguments(['', '--ros-args']) == []
    assert program_arguments(['--foxglove', '', '--ros-args', '-r', '__node:=demo']) == [
        '--foxglove']
    assert program_arguments(['--out', 'reports/x', '--lockstep']) == [
        '--out', 'reports/x', '--lockstep']
