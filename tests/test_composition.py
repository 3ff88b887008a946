"""
Integration: nodes composed into one process (launch runner --compose), over real DDS.

The minimal system (robot_controller + the kinematic robot_simulation) runs with both
nodes in one node_container process, in the test's own ROS domain, on simulated time
the test publishes: commands still cross between the nodes, Ctrl-C closes each node
(robot_controller's final zero twist), and a node that fails to start stops its
container with exit code 2 and a fatal log naming it.
"""

import os
import signal
import textwrap
import time

from geometry_msgs.msg import Twist
import pytest
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage

pytestmark = pytest.mark.integration


@pytest.fixture
def composition(tmp_path):
    path = tmp_path / 'composition.yaml'
    path.write_text('containers:\n  minimal_container: [robot_simulation, robot_controller]\n')
    return path


def test_composed_nodes_talk_and_close_on_ctrl_c(start_system, test_node, composition,
                                                  processes_with_marker):
    test_node.start_clock()
    tf = test_node.record(TFMessage, '/tf')
    cmd_vel = test_node.record(Twist, 'cmd_vel')
    status = test_node.record(String, 'control_status')
    command_pub = test_node.node.create_publisher(String, 'control_command', 10)
    system = start_system('--compose', '--composition', str(composition),
                          'mecanum_bringup', 'minimal.launch.yaml', 'use_sim_time:=true')
    system.wait_for_line(r'\[runner\] system minimal.launch.yaml: 1 nodes \(minimal_container\)')
    system.wait_for_line(r'\[minimal_container\].*\[node_container\]: 2 nodes in one process: '
                         r'robot_simulation, robot_controller')
    pid = system.node_pid('minimal_container')

    deadline = time.monotonic() + 20
    while command_pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    command_pub.publish(String(data='strafe left 0.3 m at 0.3 m/s'))
    status.wait_for(lambda m: m.data == 'done: strafe left')
    tf.wait_since(time.monotonic(), lambda m: True)   # a transform after the motion
    # robot_controller's cmd_vel reached the simulation in the same process.
    assert tf.latest().transforms[0].transform.translation.y == pytest.approx(0.3, abs=0.03)

    # Keep a motion running, then Ctrl-C: the container closes robot_controller, whose
    # last word is a zero twist.
    command_pub.publish(String(data='forward 5 m'))
    cmd_vel.wait_for_new(lambda m: m.linear.x > 0.0)
    stopping = time.monotonic()
    assert system.stop(signal.SIGINT) == 0
    assert time.monotonic() - stopping < 6.0
    deadline = time.monotonic() + 2.0   # the zero may still be on its way to us
    while cmd_vel.latest().linear.x != 0.0 and time.monotonic() < deadline:
        time.sleep(0.02)
    last = cmd_vel.latest()
    assert (last.linear.x, last.linear.y, last.angular.z) == (0.0, 0.0, 0.0)
    assert not os.path.exists(f'/proc/{pid}') or \
        open(f'/proc/{pid}/stat').read().rsplit(')', 1)[1].split()[0] == 'Z'
    assert processes_with_marker(system.marker) == []


def test_a_stalled_process_holds_the_test_clock_back(start_system, test_node, composition):
    # A loaded machine can stall a process for a second or more; the test clock (as the
    # simulator's lockstep) must wait for it, or simulated time runs on without it and
    # the motion it times comes out longer (0.396 m for 0.3 m, seen in CI).
    test_node.start_clock()
    tf = test_node.record(TFMessage, '/tf')
    status = test_node.record(String, 'control_status')
    command_pub = test_node.node.create_publisher(String, 'control_command', 10)
    system = start_system('--compose', '--composition', str(composition),
                          'mecanum_bringup', 'minimal.launch.yaml', 'use_sim_time:=true')
    pid = system.node_pid('minimal_container')
    deadline = time.monotonic() + 20
    while command_pub.get_subscription_count() == 0:
        assert time.monotonic() < deadline, 'robot_controller does not subscribe'
        time.sleep(0.05)
    # The clock waits for the container only once it has answered a /clock (it answers
    # once it has discovered the test's /clock_ack subscription): before, a stall went
    # unnoticed, time ran on and the motion timed out (0.096 m for 0.3 m, CI here).
    test_node.clock_acks.wait_for_participant('robot_simulation')
    command_pub.publish(String(data='strafe left 0.3 m at 0.3 m/s'))
    status.wait_for(lambda m: m.data.startswith('accepted: strafe left'))
    os.kill(pid, signal.SIGSTOP)
    try:
        time.sleep(1.6)   # the stall itself: longer than 1 s, shorter than 3 s
    finally:
        os.kill(pid, signal.SIGCONT)
    status.wait_for(lambda m: m.data == 'done: strafe left')
    done_at = time.monotonic()
    tf.wait_since(done_at, lambda m: True)   # a transform sent after the motion ended
    y = tf.latest().transforms[0].transform.translation.y
    assert y == pytest.approx(0.3, abs=0.03)


def test_a_node_that_cannot_start_stops_its_container(start_system, tmp_path, composition):
    launch = tmp_path / 'bad.launch.yaml'
    launch.write_text(textwrap.dedent("""
        launch:
        - node:
            pkg: robot_simulation
            exec: simulation_node
            name: robot_simulation
        - node:
            pkg: robot_controller
            exec: robot_control_node
            name: robot_controller
            on_exit: shutdown
            param:
            - {name: publish_rate_hz, value: -1.0}
        """))
    system = start_system('--compose', '--composition', str(composition), str(launch))
    system.wait_for_line(r'\[FATAL\].*\[robot_controller\]: publish_rate_hz must be positive')
    system.wait_for_line(r'\[runner\] minimal_container exited with code 2')
    assert system.process.wait(timeout=15) == 2
