"""Fixtures: the test bag written with the project's BagWriter."""

from pathlib import Path
import sys

import pytest

# The sources under test (also before the package is built, and before an older build),
# and this folder's bag_samples.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bag_samples import cdr_string, MESSAGES  # noqa: E402, I100


@pytest.fixture
def project_bag(tmp_path):
    """Write the test bag with mecanum_bringup's BagWriter; return its folder."""
    bag_writer = pytest.importorskip('mecanum_bringup.bag_writer')
    directory = tmp_path / 'test_bag'
    writer = bag_writer.BagWriter(str(directory), ros_distro='jazzy')
    writer.add_topic('/chatter', 'std_msgs/msg/String', [bag_writer.OfferedQos()])
    writer.add_topic('/latched', 'std_msgs/msg/String',
                     [bag_writer.OfferedQos(durability='transient_local', depth=1)])
    for topic, log_time, text in MESSAGES:
        writer.write(topic, cdr_string(text), log_time)
    writer.close()
    return directory
