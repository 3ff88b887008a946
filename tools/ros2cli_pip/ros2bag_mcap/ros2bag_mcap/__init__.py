"""``ros2 bag`` (info, play, record) for the pip setup: MCAP bags, without rosbag2's C++."""
