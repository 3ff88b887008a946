"""
Integration: robot_controller as a source of the command chain, over real DDS.

robot_controller runs alone (launch_runner, its own ROS domain, simulated time that
this test publishes on /clock) with an authorised zone: a 3 m x 3 m room. The test
plays everything around it: /tf (map -> odom -> base_link, the robot at (1, 1) facing
+x) and the command chain, which either passes what robot_controller sends on
cmd_vel_text on to cmd_vel_safe, holds the robot (zero on cmd_vel_safe and
'STOP PolygonStop' on collision_monitor_state, as the collision monitor does), or says
nothing at all.
"""

from pathlib import Path
import re
import subprocess
import threading
import time

from geometry_msgs.msg import TransformStamped, Twist
from mecanum_safety.zone import make_zone, zone_file_text
import pytest
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage
import yaml

pytestmark = pytest.mark.integration

NO_POSE = ('rejected: cannot check the authorised zone: no recent map -> base_link pose '
           '(is localisation running?)')


def write_launch(directory):
    """Write the zone file and the launch file of robot_controller alone; return its path."""
    zone_path = directory / 'zone.yaml'
    zone_path.write_text(zone_file_text(make_zone([[0, 0], [3, 0], [3, 3], [0, 3]])))
    launch = {'launch': [{'node': {
        'pkg': 'robot_controller', 'exec': 'robot_control_node', 'name': 'robot_controller',
        'param': [
            {'from': '$(find-pkg-share robot_controller)/config/robot_controller.yaml'},
            {'from': '$(find-pkg-share mecanum_control)/config/motor_params.yaml'},
            {'name': 'zone_file', 'value': str(zone_path)},
            {'name': 'chain_start_timeout_s', 'value': 2.0},
            {'name': 'use_sim_time', 'value': True}],
        # As in every launch file with the chain: its text-command input.
        'remap': [{'from': 'cmd_vel', 'to': 'cmd_vel_text'}]}}]}
    path = directory / 'robot_controller_chain.launch.yaml'
    path.write_text(yaml.safe_dump(launch, sort_keys=False))
    return path


class World:
    """The robot's pose on /tf and the command chain, played by the test node."""

    def __init__(self, test_node):
        """Create the publishers; the chain passes commands on until told otherwise."""
        self.test_node = test_node
        node = test_node.node
        self.chain = 'pass'        # 'pass', 'block' or 'silent'
        self.publishing_tf = threading.Event()
        self.tf_pub = node.create_publisher(TFMessage, '/tf', 100)
        self.safe_pub = node.create_publisher(Twist, 'cmd_vel_safe', 10)
        self.state_pub = node.create_publisher(String, 'collision_monitor_state', 10)
        node.create_subscription(Twist, 'cmd_vel_text', self.on_command, 10)
        threading.Thread(target=self._publish_tf, daemon=True).start()

    def on_command(self, msg):
        """Play the chain: one output (and state) per input, as its stages do."""
        if self.chain == 'pass':
            self.safe_pub.publish(msg)
            self.state_pub.publish(String(data='DO_NOTHING'))
        elif self.chain == 'block':
            self.safe_pub.publish(Twist())
            self.state_pub.publish(String(data='STOP PolygonStop'))

    def _publish_tf(self):
        while self.test_node.context.ok():
            if self.publishing_tf.is_set():
                sec, nanosec = divmod(self.test_node.clock_ns, 10 ** 9)
                msg = TFMessage(transforms=[self._transform('map', 'odom', 0.0, sec, nanosec),
                                            self._transform('odom', 'base_link', 1.0, sec,
                                                            nanosec)])
                try:
                    self.tf_pub.publish(msg)
                except Exception:  # noqa: B902 - context shut down
                    return
            time.sleep(0.05)

    @staticmethod
    def _transform(parent, child, xy, sec, nanosec):
        msg = TransformStamped()
        msg.header.frame_id, msg.child_frame_id = parent, child
        msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
        msg.transform.translation.x = msg.transform.translation.y = xy
        msg.transform.rotation.w = 1.0
        return msg


def is_zero(twist):
    return (twist.linear.x, twist.linear.y, twist.angular.z) == (0.0, 0.0, 0.0)


def test_zone_refusal_and_stop_short(start_system, test_node, tmp_path):
    node = test_node.node
    test_node.start_clock()
    world = World(test_node)
    status = test_node.record(String, 'control_status')
    cmd = test_node.record(Twist, 'cmd_vel_text')
    command_pub = node.create_publisher(String, 'control_command', 10)

    def send(text):
        start = time.monotonic()
        command_pub.publish(String(data=text))
        return start

    system = start_system(str(write_launch(tmp_path)))
    system.wait_for_line(r'\[robot_controller\].*ready.*/cmd_vel_text; zone .*watching '
                         r'/cmd_vel_safe')
    deadline = time.monotonic() + 20
    while command_pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.05)

    # No pose: every command but stop is refused, and nothing is sent.
    start = send('forward 0.2 m')
    status.wait_since(start, lambda m: m.data == NO_POSE, timeout=10.0)
    start = send('stop')
    status.wait_since(start, lambda m: m.data == 'done: stop', timeout=10.0)
    assert all(is_zero(m) for m in cmd.since(0.0))

    # The pose arrives just after a command (localisation starting up): the command
    # waits for it, up to pose_timeout_s (1 s), and is accepted, not refused.
    holding = r"Holding 'forward 0.2 m' until a recent map -> base_link pose arrives"
    assert len(re.findall(holding, system.output())) == 1   # the refused command's wait
    start = send('forward 0.2 m')
    deadline = time.monotonic() + 10
    while len(re.findall(holding, system.output())) < 2:
        assert time.monotonic() < deadline, system.output()
        time.sleep(0.02)
    world.publishing_tf.set()
    reply = status.wait_since(
        start, lambda m: m.data.startswith(('accepted', 'rejected')), timeout=10.0)
    assert reply.data == 'accepted: forward 0.2 m'
    # Accepted: it drives through the (passing) chain for its 1 s and ends done.
    cmd.wait_since(start, lambda m: m.linear.x == pytest.approx(0.2), timeout=10.0)
    status.wait_since(start, lambda m: m.data.startswith(('done', 'stopped')), timeout=10.0)
    assert [m.data for m in status.since(start)][-1] == 'done: forward'
    cmd.wait_since(start, is_zero, timeout=10.0)   # its final zero twist

    # A command leaving the zone is refused before it starts: no twist at all. The stop
    # that follows sends one zero twist; anything the refused command had sent would
    # have arrived before it (one writer: in order).
    start = send('forward 2 m')
    status.wait_since(start, lambda m: m.data.startswith('rejected'), timeout=10.0)
    replies = [m.data for m in status.since(start)]
    # From (1, 1) east: 0.25 m (footprint + margin) from the border x = 3 at x = 2.75.
    assert len(replies) == 1 and replies[0].startswith('rejected: forward 2 m: ')
    assert 'authorised zone at (2.76, 1.00)' in replies[0]
    system.wait_for_line(r'\[robot_controller\].*Rejected command .forward 2 m.')
    send('stop')
    status.wait_since(start, lambda m: m.data == 'done: stop', timeout=10.0)
    cmd.wait_since(start, is_zero, timeout=10.0)
    assert len(cmd.since(start)) == 1

    # The chain holds the robot: the motion stops short after blocked_time_s (0.5 s).
    world.chain = 'block'
    start = send('strafe left 1 m')        # 5 s if not held
    status.wait_since(start, lambda m: m.data == 'accepted: strafe left 1 m', timeout=10.0)
    accepted_ns = test_node.clock_ns
    status.wait_since(start, lambda m: m.data.startswith(('done', 'stopped')), timeout=10.0)
    held_s = (test_node.clock_ns - accepted_ns) * 1e-9
    assert [m.data for m in status.since(start)][-1] == \
        'stopped: strafe left blocked by collision_monitor STOP PolygonStop'
    assert 0.45 <= held_s <= 1.5
    system.wait_for_line(r'\[robot_controller\].*Stopping .strafe left 1 m. short')
    # It sent its twist until then, then one zero twist and nothing more (the stop's
    # zero twist comes next).
    stop_start = send('stop')
    status.wait_since(stop_start, lambda m: m.data == 'done: stop', timeout=10.0)
    deadline = time.monotonic() + 10
    while sum(is_zero(m) for m in cmd.since(start)) < 2 and time.monotonic() < deadline:
        time.sleep(0.02)
    twists = cmd.since(start)
    first_zero = next(i for i, m in enumerate(twists) if is_zero(m))
    assert first_zero >= 1 and all(m.linear.y == pytest.approx(0.2)
                                   for m in twists[:first_zero])
    assert all(is_zero(m) for m in twists[first_zero:]) and len(twists) == first_zero + 2

    # The chain says nothing at all (e.g. it is down): stopped as well, once
    # chain_start_timeout_s (2 s here) has passed without a first output.
    world.chain = 'silent'
    start = send('rotate left 3 s')
    status.wait_since(start, lambda m: m.data == 'accepted: rotate left 3 s', timeout=10.0)
    accepted_ns = test_node.clock_ns
    status.wait_since(start, lambda m: m.data.startswith(('done', 'stopped')), timeout=10.0)
    silent_s = (test_node.clock_ns - accepted_ns) * 1e-9
    assert [m.data for m in status.since(start)] == [
        'accepted: rotate left 3 s',
        'stopped: rotate left blocked by no output from the command chain']
    assert 1.95 <= silent_s <= 3.0
    cmd.wait_since(start, is_zero, timeout=10.0)

    # A chain that passes the command late (still discovering its stages): the motion
    # is timed from its first output, so it still lasts its full 1 s after that.
    start = send('forward 0.2 m')
    status.wait_since(start, lambda m: m.data == 'accepted: forward 0.2 m', timeout=10.0)
    test_node.wait_sim(1.0, timeout=10.0)
    world.chain = 'pass'
    passing_ns = test_node.clock_ns
    status.wait_since(start, lambda m: m.data.startswith(('done', 'stopped')), timeout=10.0)
    assert [m.data for m in status.since(start)][-1] == 'done: forward'
    assert (test_node.clock_ns - passing_ns) * 1e-9 >= 0.95

    # The pose goes stale (older than pose_timeout_s, 1 s): refused again.
    world.publishing_tf.clear()
    stale_from_ns = test_node.clock_ns
    deadline = time.monotonic() + 10
    while test_node.clock_ns - stale_from_ns < 1.3e9 and time.monotonic() < deadline:
        time.sleep(0.02)
    start = send('forward 0.2 m')
    status.wait_since(start, lambda m: m.data == NO_POSE, timeout=10.0)


def test_a_motion_waits_for_a_subscriber_and_then_lasts_its_full_duration(
        start_system, test_node, tmp_path):
    """
    With no chain watched and nobody subscribed to cmd_vel, a command is held.

    A base that DDS discovery finds late would otherwise miss the start of the motion
    (CI saw the minimal system strafe 0.20 m of a 0.3 m command). Once a subscriber
    appears, the motion starts and lasts its whole duration from its first twist.
    """
    node = test_node.node
    test_node.start_clock()
    launch = {'launch': [{'node': {
        'pkg': 'robot_controller', 'exec': 'robot_control_node', 'name': 'robot_controller',
        'param': [{'name': 'chain_output_topic', 'value': ''},
                  {'name': 'use_sim_time', 'value': True}]}}]}
    path = tmp_path / 'robot_controller_alone.launch.yaml'
    path.write_text(yaml.safe_dump(launch, sort_keys=False))
    status = test_node.record(String, 'control_status')
    command_pub = node.create_publisher(String, 'control_command', 10)
    system = start_system(str(path))
    system.wait_for_line(r'\[robot_controller\].*ready.*not watching the command chain')
    deadline = time.monotonic() + 20
    while command_pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    command_pub.publish(String(data='strafe left 0.5 m at 0.25 m/s'))   # 2 s
    system.wait_for_line(r"Holding 'strafe left 0.5 m at 0.25 m/s' until something "
                         r'subscribes to /cmd_vel')
    # Held for more than the motion's duration: nothing is sent, it is not done.
    test_node.wait_sim(2.5)
    assert not any(m.data.startswith('done') for m in status.since(0.0))

    twist_times_ns = []
    node.create_subscription(Twist, 'cmd_vel',
                             lambda msg: twist_times_ns.append((test_node.clock_ns, msg)), 10)
    status.wait_for(lambda m: m.data == 'done: strafe left', timeout=30.0)
    moving = [when for when, msg in twist_times_ns if msg.linear.y == 0.25]
    assert moving, 'no twist of the motion was received'
    stopped = [when for when, msg in twist_times_ns if is_zero(msg) and when >= moving[0]]
    assert stopped, 'the motion did not end with a zero twist'
    # 2 s from the first twist received, to within the 20 Hz publishing period and the
    # delivery of /clock to both processes.
    assert (stopped[0] - moving[0]) * 1e-9 == pytest.approx(2.0, abs=0.1)


@pytest.mark.parametrize('parameter, value, message', [
    ('zone_file', '/nonexistent/zone.yaml', 'cannot read the zone file'),
    ('zone_margin_m', '-0.1', 'parameter zone_margin_m must be finite and >= 0'),
    ('pose_timeout_s', '0.0', 'parameter pose_timeout_s must be finite and > 0'),
    ('blocked_speed_ratio', '1.5', r'parameter blocked_speed_ratio must be within \(0, 1\)'),
    ('global_frame', "''", 'parameter global_frame must name a frame'),
])
def test_bad_parameters_stop_the_node_with_a_clear_message(ros_env, parameter, value,
                                                           message):
    """The node exits 2 with the reason at FATAL level and no traceback."""
    result = subprocess.run(
        ['./mecanum', 'run', 'robot_controller', 'robot_control_node', '--ros-args', '-p',
         f'{parameter}:={value}'], env=ros_env, capture_output=True, text=True, timeout=60,
        cwd=str(Path(__file__).resolve().parents[1]))
    output = result.stdout + result.stderr
    assert result.returncode == 2, output
    assert 'Traceback' not in output
    assert re.search(r'\[FATAL\].*' + message, output), output
