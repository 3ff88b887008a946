"""
Integration: `ros2 bag` (info, play, record) in the pip setup, the real command.

The pip setup cannot build rosbag2 (C++); tools/ros2cli_pip/ros2bag_mcap adds the `bag`
command to the upstream ros2cli. These tests run `ros2 bag` as a subprocess in a leased
ROS domain, on a small bag written here with the project's BagWriter: 8 std_msgs/String
messages 0.1 s apart, '0' to '7', alternating /bag_test/chatter (volatile, the even
ones) and /bag_test/latched (transient local, the odd ones), from START_NS.

Discovery between the player and the test node takes a moment (seconds on a busy
machine) and, as with rosbag2, nothing waits for it: the first messages of a volatile
topic may be lost. So the plays loop (``--loop``) and the tests wait for a complete,
ordered pass among what arrived; timing is compared as ratios of spans measured in the
same test, never against absolute durations. Every play is stopped with SIGINT (Ctrl-C)
and must exit 0 without a traceback.
"""

import importlib.util
from pathlib import Path
import shutil
import signal
import statistics
import subprocess
import time

from mcap.reader import make_reader
import pytest
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String
from tests.conftest import OutputProcess, Recorder

pytestmark = pytest.mark.integration

ROS2 = shutil.which('ros2')
S = 10 ** 9
START_NS = 1_700_000_000 * S
CHATTER = '/bag_test/chatter'
LATCHED = '/bag_test/latched'
MESSAGES = [(CHATTER if i % 2 == 0 else LATCHED, START_NS + i * S // 10, str(i))
            for i in range(8)]
PASS = [str(i) for i in range(8)]
END_NS = MESSAGES[-1][1]
#: Longest wait for an event (discovery, a pass of the bag), s.
TIMEOUT_S = 60.0
#: The pip setup's `ros2 bag` (not rosbag2's, on an apt install): its error messages.
PIP_ROS2BAG = importlib.util.find_spec('ros2bag_mcap') is not None


def ros2_bag_available() -> bool:
    """Tell whether `ros2 bag --help` works (the command is built and on the PATH)."""
    if ROS2 is None:
        return False
    result = subprocess.run([ROS2, 'bag', '--help'], capture_output=True, text=True,
                            timeout=60)
    return result.returncode == 0 and 'play' in result.stdout


@pytest.fixture(scope='module', autouse=True)
def needs_ros2_bag():
    """Skip, saying why, where `ros2 bag` is not built (ros2bag_mcap not installed)."""
    if not ros2_bag_available():
        pytest.skip('`ros2 bag --help` fails: the ros2bag_mcap command extension '
                    '(tools/ros2cli_pip/ros2bag_mcap) is not built into this environment')


@pytest.fixture
def bag(tmp_path) -> Path:
    """Write the test bag with the project's BagWriter; return its folder."""
    from mecanum_bringup.bag_writer import BagWriter, OfferedQos
    directory = tmp_path / 'test_bag'
    with BagWriter(str(directory), ros_distro='jazzy') as writer:
        writer.add_topic(CHATTER, 'std_msgs/msg/String', [OfferedQos()])
        writer.add_topic(LATCHED, 'std_msgs/msg/String',
                         [OfferedQos(durability='transient_local', depth=1)])
        for topic, log_time, text in MESSAGES:
            writer.write(topic, serialize_message(String(data=text)), log_time)
    return directory


def ros2_bag(env, *args, timeout=TIMEOUT_S) -> subprocess.CompletedProcess:
    """Run `ros2 bag ARGS` to its end."""
    return subprocess.run([ROS2, 'bag', *args], env=env, capture_output=True, text=True,
                          timeout=timeout)


class Play(OutputProcess):
    """`ros2 bag play BAG ARGS` running; stop() sends Ctrl-C and checks a clean exit."""

    def __init__(self, env, bag: Path, *args: str):
        super().__init__([ROS2, 'bag', 'play', str(bag), *args], env)

    def stop(self) -> None:
        """Send SIGINT; the player must exit 0 without a traceback."""
        self.process.send_signal(signal.SIGINT)
        self.process.wait(timeout=30)
        self._reader.join(timeout=5)
        assert self.process.returncode == 0, self.output()
        assert 'Traceback' not in self.output(), self.output()

    def __enter__(self):
        """Use in a with block: stopped (and checked) at its end."""
        return self

    def __exit__(self, exc_type, *_):
        """Stop the player; on a failure already raised, only make sure it is gone."""
        if exc_type is None:
            self.stop()
        elif self.process.poll() is None:
            self.process.kill()
            self.process.wait(timeout=10)


def arrivals(*recorders) -> list:
    """Return (arrival monotonic s, data) of the recorders' messages, in arrival order."""
    received = []
    for recorder in recorders:
        with recorder._lock:
            received += [(when, msg.data) for when, msg in recorder.messages]
    return sorted(received, key=lambda pair: pair[0])


def complete_passes(received: list, expected: list) -> list:
    """Return the arrival times of each run of `expected` received in a row, in order."""
    data = [d for _, d in received]
    return [[when for when, _ in received[i:i + len(expected)]]
            for i in range(len(data) - len(expected) + 1)
            if data[i:i + len(expected)] == expected]


def wait_for_passes(expected: list, count: int, *recorders) -> list:
    """Wait until `count` complete passes of `expected` arrived in a row; return them."""
    deadline = time.monotonic() + TIMEOUT_S
    while True:
        passes = complete_passes(arrivals(*recorders), expected)
        if len(passes) >= count:
            return passes
        assert time.monotonic() < deadline, (
            f'{len(passes)} of {count} complete passes of {expected}; received '
            f'{[d for _, d in arrivals(*recorders)][-40:]}')
        time.sleep(0.05)


def test_info_shows_the_bag_as_rosbag2_does(ros_env, bag, tmp_path):
    result = ros2_bag(ros_env, 'info', str(bag))
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0] == ''
    assert 'Files:             test_bag_0.mcap' in lines
    assert 'Storage id:        mcap' in lines
    assert 'ROS Distro:        jazzy' in lines
    assert 'Duration:          0.700000000s' in lines
    assert 'Messages:          8' in lines
    assert any(line.startswith('Start:') and line.endswith('(1700000000.000000000)')
               for line in lines), result.stdout
    assert any(line.startswith('End:') and line.endswith('(1700000000.700000000)')
               for line in lines), result.stdout
    topics = result.stdout.split('Topic information: ')[1].split('Service:')[0]
    assert [line.strip() for line in topics.splitlines()] == [
        f'Topic: {CHATTER} | Type: std_msgs/msg/String | Count: 4 | Serialization Format: cdr',
        f'Topic: {LATCHED} | Type: std_msgs/msg/String | Count: 4 | Serialization Format: cdr']
    # The MCAP file alone says the same (from its summary).
    single = ros2_bag(ros_env, 'info', str(bag / 'test_bag_0.mcap'))
    assert single.returncode == 0, single.stderr
    assert single.stdout.split('Storage id:')[1] == result.stdout.split('Storage id:')[1]
    # Bad input: an error, and with the pip setup's ros2 bag one line on stderr, exit
    # code 1, no traceback.
    truncated = tmp_path / 'truncated.mcap'
    truncated.write_bytes((bag / 'test_bag_0.mcap').read_bytes()[:300])
    for path, words in ((tmp_path / 'missing', 'does not exist'),
                        (truncated, 'truncated or corrupt')):
        failed = ros2_bag(ros_env, 'info', str(path))
        assert failed.returncode != 0, failed
        if PIP_ROS2BAG:
            assert failed.returncode == 1, failed
            assert failed.stdout == '' and words in failed.stderr, failed
            assert len(failed.stderr.strip().splitlines()) == 1, failed.stderr


def test_play_delivers_every_message_in_order_and_ends_by_itself(ros_env, bag, test_node):
    chatter = test_node.record(String, CHATTER)
    latched = test_node.record(String, LATCHED, latched=True)
    # --delay 0.3: a pause between passes, so that a pass's last message ('7') and the
    # next one's first ('0'), published back to back, cannot arrive swapped.
    with Play(ros_env, bag, '--loop', '--delay', '0.3'):
        # Whole passes, both topics interleaved as recorded.
        wait_for_passes(PASS, 2, chatter, latched)
    # Without --loop the player ends by itself (exit code 0) after the last message.
    result = ros2_bag(ros_env, 'play', str(bag), '--rate', '10')
    assert result.returncode == 0, result.stderr
    assert 'Traceback' not in result.stderr


def test_play_topics_plays_only_those(ros_env, bag, test_node):
    chatter = test_node.record(String, CHATTER)
    latched = test_node.record(String, LATCHED, latched=True)
    with Play(ros_env, bag, '--loop', '--topics', LATCHED):
        wait_for_passes(['1', '3', '5', '7'] * 3, 1, latched)
        # Three passes of /bag_test/latched went by: no /bag_test/chatter message; and
        # once the player's publishers are in the graph, none on /bag_test/chatter.
        assert chatter.messages == []
        deadline = time.monotonic() + TIMEOUT_S
        while test_node.node.count_publishers(LATCHED) < 1:
            assert time.monotonic() < deadline, 'the player never showed in the graph'
            time.sleep(0.05)
        assert test_node.node.count_publishers(CHATTER) == 0


def pass_spans(env, bag, test_node, *args) -> list:
    """Play with --loop and args; return the arrival spans (s) of '0' to '6' in 3 passes."""
    chatter = test_node.record(String, CHATTER)
    with Play(env, bag, '--loop', *args):
        passes = wait_for_passes(['0', '2', '4', '6'], 3, chatter)
    return [times[-1] - times[0] for times in passes[:3]]


def test_play_rate_two_halves_the_spacing(ros_env, bag, test_node):
    normal = statistics.median(pass_spans(ros_env, bag, test_node))
    double = statistics.median(pass_spans(ros_env, bag, test_node, '--rate', '2'))
    # Recorded: 0.6 s from '0' to '6'; at rate 2, 0.3 s. Loosely: the ratio is about 2.
    assert 1.4 < normal / double < 2.9, (normal, double)


def test_play_clock_publishes_the_bag_time(ros_env, bag, test_node):
    clock = Recorder(test_node.node, Clock, '/clock', qos_profile_sensor_data)  # best effort
    chatter = test_node.record(String, CHATTER)
    with Play(ros_env, bag, '--loop', '--clock', '50'):
        wait_for_passes(['0', '2', '4', '6'], 2, chatter)
        deadline = time.monotonic() + TIMEOUT_S
        while True:
            with clock._lock:
                stamps = [m.clock.sec * S + m.clock.nanosec for _, m in clock.messages]
            if any(s <= START_NS + S // 10 for s in stamps) and \
                    any(s >= START_NS + 6 * S // 10 for s in stamps):
                break
            assert time.monotonic() < deadline, f'/clock: {stamps[-20:]}'
            time.sleep(0.05)
    # Bag time: within the bag's span, going forward, and back to the start at each new
    # pass of the loop.
    outside = [(i, s - START_NS) for i, s in enumerate(stamps)
               if not START_NS <= s <= END_NS + S // 20]
    assert outside == [], (f'/clock outside the bag (index, ns after its start; the bag '
                           f'spans {END_NS - START_NS} ns) of {len(stamps)}: {outside[:10]}')
    for before, after in zip(stamps, stamps[1:]):
        assert after >= before or after <= START_NS + S // 10, (before, after)


def test_record_writes_what_was_published(ros_env, test_node, tmp_path):
    output = tmp_path / 'recorded'
    topic, marker = '/bag_test/recorded', '/bag_test/marker'
    recorder = OutputProcess([ROS2, 'bag', 'record', '-o', str(output), topic, marker],
                             ros_env)
    try:
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        publisher = test_node.node.create_publisher(String, topic, reliable)
        # (rosbag2 quotes the name, the pip setup's recorder does not)
        recorder.wait_for_line(rf"Subscribed to topic '?{topic}\b", TIMEOUT_S)
        deadline = time.monotonic() + TIMEOUT_S
        while publisher.get_subscription_count() < 1:
            assert time.monotonic() < deadline, 'the recorder never matched'
            time.sleep(0.05)
        texts = [f'recorded {i}' for i in range(5)]
        for text in texts:
            publisher.publish(String(data=text))
        assert publisher.wait_for_all_acked(), 'the recorder did not acknowledge'
        # The recorder handles its events in order: once it subscribed to a topic that
        # appeared after those messages were acknowledged, it has taken them.
        test_node.node.create_publisher(String, marker, reliable).publish(String(data='x'))
        recorder.wait_for_line(rf"Subscribed to topic '?{marker}\b", TIMEOUT_S)
        recorder.process.send_signal(signal.SIGINT)
        assert recorder.process.wait(timeout=30) == 0, recorder.output()
    finally:
        if recorder.process.poll() is None:
            recorder.process.kill()
            recorder.process.wait(timeout=10)
    assert 'Traceback' not in recorder.output(), recorder.output()
    info = ros2_bag(ros_env, 'info', str(output))
    assert info.returncode == 0, info.stderr
    assert f'Topic: {topic} | Type: std_msgs/msg/String | Count: 5 | ' \
        'Serialization Format: cdr' in info.stdout, info.stdout
    with open(output / 'recorded_0.mcap', 'rb') as stream:
        recorded = [deserialize_message(message.data, String).data
                    for _, channel, message in make_reader(stream).iter_messages()
                    if channel.topic == topic]
    assert recorded == texts
