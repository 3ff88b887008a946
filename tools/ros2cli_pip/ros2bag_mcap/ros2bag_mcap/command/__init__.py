"""The ``bag`` command of the ros2 command line tools."""
