"""
Integration: hardware_interface.catch_up() takes in every frame the board sent so far.

node_main.ClockAnswer calls it before the process takes a /clock, so that the frames the
simulated board wrote before that /clock are handled at the time before, however far the
serial reader thread has got. Here the node runs in the test process on a real pty (the
test plays the board with the shared protocol code) while its reader thread runs: after
each burst of frames written to the line, catch_up() returns only once every one of them
has been handled, whoever read it.
"""

import os
import time
import tty

from mecanum_control import esp32_protocol as proto
from mecanum_control.hardware_interface import HardwareInterface
import pytest
import rclpy
from rclpy.parameter import Parameter

pytestmark = pytest.mark.integration


@pytest.fixture
def board_and_node(ros_env, monkeypatch, tmp_path):
    """Return (pty master fd, HardwareInterface node) connected over a real pty."""
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    master, slave = os.openpty()
    tty.setraw(slave)
    link = tmp_path / 'ttyBOARD'
    os.symlink(os.ttyname(slave), link)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=int(ros_env['ROS_DOMAIN_ID']))
    node = HardwareInterface(context=context,
                             parameter_overrides=[Parameter('port', value=str(link))])
    try:
        yield master, node
    finally:
        node.close()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        os.close(master)
        os.close(slave)


def test_catch_up_returns_once_every_frame_sent_is_handled(board_and_node):
    master, node = board_and_node
    deadline = time.monotonic() + 10.0
    while node._serial is None:          # connect() runs in the constructor and retries
        assert time.monotonic() < deadline, 'hardware_interface did not open the pty'
        time.sleep(0.01)
    sent = 0
    for burst in range(200):
        frames = b''.join(
            proto.encode_frame(proto.EncoderTicks(1000 * sent + i, (i, i, i, i)), sent + i)
            for i in range(5))
        os.write(master, frames)
        sent += 5
        node.catch_up()
        assert node._frames_this_connection == sent, (
            f'burst {burst}: {node._frames_this_connection} of {sent} frames handled when '
            'catch_up returned')
