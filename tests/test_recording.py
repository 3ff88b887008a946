"""
Integration: recording the simulation (bag_recorder) and viewing it live (foxglove_bridge).

The system (a launch file written here): robot_simulation's physics simulator_node
(the source of /clock; scan, ground_truth/odom, latched /tf_static base_link -> laser
and /simulation/collisions; no board link), the kinematic simulation_node on
simulated time (odom, /tf, robot_status) and the node under test, on simulated time.
The bag is read back with mcap + mcap_ros2; the live view is read by a minimal
WebSocket client written here (raw sockets) speaking the Foxglove protocol that
foxglove-sdk serves (subprotocol foxglove.sdk.v1; the ROS foxglove_bridge's
foxglove.websocket.v1 is offered too).
"""

import base64
import hashlib
import json
import os
from pathlib import Path
import re
import socket
import struct
import subprocess
import time

from mcap.reader import make_reader
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory
from mecanum_bringup.message_definitions import message_definition
import pytest
import yaml

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[1]
S = 10 ** 9
SIMULATION = [
    {'node': {'pkg': 'robot_simulation', 'exec': 'simulator_node', 'name': 'simulator',
              'param': [{'name': 'world', 'value': 'apartment'},
                        {'name': 'board_port', 'value': ''}]}},
    {'node': {'pkg': 'robot_simulation', 'exec': 'simulation_node', 'name': 'robot_simulation',
              'param': [{'name': 'use_sim_time', 'value': True}]}},
]


def write_launch(directory: Path, node: dict) -> Path:
    """Write the simulation plus one node (on simulated time) as a launch file."""
    node['param'].append({'name': 'use_sim_time', 'value': True})
    path = directory / 'recording_test.launch.yaml'
    path.write_text(yaml.safe_dump({'launch': SIMULATION + [{'node': node}]}, sort_keys=False))
    return path


def decoder_for(type_name: str, definition: str):
    """Return an mcap_ros2 CDR decoder for a type from its ros2msg definition."""
    schema = Schema(id=1, name=type_name, encoding='ros2msg', data=definition.encode())
    return DecoderFactory().decoder_for('cdr', schema)


# The simulator runs at real time here (no lockstep): each /clock's log time is when the
# recorder received it, 0.62 s late once on a machine loaded by a sweep beside make test.
@pytest.mark.alone
def test_recorder_writes_a_complete_bag_of_the_simulation(start_system, tmp_path):
    """Record a few seconds, stop with Ctrl-C, read the bag back: complete and consistent."""
    bag = tmp_path / 'sim_bag'
    system = start_system(str(write_launch(tmp_path, {
        'pkg': 'mecanum_bringup', 'exec': 'bag_recorder', 'name': 'bag_recorder',
        'param': [{'name': 'output', 'value': str(bag)},
                  {'name': 'exclude', 'value': '^/parameter_events$'}]})))
    for topic in ('/clock', '/scan', '/tf_static', '/simulation/collisions', '/odom', '/tf'):
        system.wait_for_line(rf'\[bag_recorder\].*Subscribed to topic {topic} ', 30.0)
    time.sleep(4.0)  # record a few seconds
    assert system.stop() == 0
    system.wait_for_line(r'\[bag_recorder\].*Bag .* closed: \d+ messages')
    assert 'Traceback' not in system.output()

    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['relative_file_paths'] == ['sim_bag_0.mcap']
    with open(bag / 'sim_bag_0.mcap', 'rb') as file:
        reader = make_reader(file, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        decoded = {}
        for _, channel, message, msg in reader.iter_decoded_messages(log_time_order=False):
            decoded.setdefault(channel.topic, []).append((message, msg))

    # Counts agree between the MCAP summary, its messages and metadata.yaml.
    channels = {c.id: c.topic for c in summary.channels.values()}
    mcap_counts = {channels[i]: n for i, n in summary.statistics.channel_message_counts.items()}
    yaml_counts = {t['topic_metadata']['name']: t['message_count']
                   for t in info['topics_with_message_count']}
    assert mcap_counts == yaml_counts == {t: len(m) for t, m in decoded.items()}
    assert info['message_count'] == summary.statistics.message_count == sum(yaml_counts.values())
    assert info['starting_time']['nanoseconds_since_epoch'] == \
        summary.statistics.message_start_time
    assert info['duration']['nanoseconds'] == \
        summary.statistics.message_end_time - summary.statistics.message_start_time
    expected = {'/clock', '/scan', '/ground_truth/odom', '/tf_static', '/simulation/collisions',
                '/odom', '/tf', '/robot_status', '/rosout'}
    assert expected <= set(yaml_counts), f'recorded: {sorted(yaml_counts)}'
    assert '/parameter_events' not in yaml_counts  # excluded

    # Log times are simulated receive times: each /clock message is logged at its time.
    for message, clock in decoded['/clock']:
        clock_ns = clock.clock.sec * S + clock.clock.nanosec
        assert abs(message.log_time - clock_ns) < S // 2
    # Every scan was recorded (stamps 0.1 s apart, no gap) and decodes field by field.
    scans = [msg for _, msg in decoded['/scan']]
    print(f'{info["message_count"]} messages, {len(scans)} scans, '
          f'{info["duration"]["nanoseconds"] / S:.2f} s simulated')
    assert len(scans) >= 5
    stamps = sorted(m.header.stamp.sec * S + m.header.stamp.nanosec for m in scans)
    assert all(0.095 * S <= b - a <= 0.105 * S for a, b in zip(stamps, stamps[1:]))
    for scan in scans:
        assert scan.header.frame_id == 'laser'
        assert len(scan.ranges) == 360 and scan.range_max == pytest.approx(12.0)
        assert scan.angle_increment == pytest.approx(2 * 3.14159265 / 360, rel=1e-3)
    # Latched topics published before the recorder subscribed are in the bag.
    (_, static), = decoded['/tf_static']
    assert [(t.header.frame_id, t.child_frame_id) for t in static.transforms] == [
        ('base_link', 'laser')]
    assert [m.data for _, m in decoded['/simulation/collisions']] == [0]
    qos = [t['topic_metadata']['offered_qos_profiles'] for t in info['topics_with_message_count']
           if t['topic_metadata']['name'] == '/tf_static'][0]
    assert qos[0]['durability'] == 'transient_local'
    truth = decoded['/ground_truth/odom'][-1][1]
    assert truth.child_frame_id == 'base_link'


class FoxgloveClient:
    """A minimal WebSocket client (RFC 6455) for the Foxglove protocol, on a raw socket."""

    PROTOCOLS = 'foxglove.sdk.v1, foxglove.websocket.v1'

    def __init__(self, port: int):
        """Connect and complete the WebSocket opening handshake."""
        self.sock = socket.create_connection(('127.0.0.1', port), timeout=10)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall((
            f'GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n'
            f'Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n'
            f'Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: {self.PROTOCOLS}\r\n'
            '\r\n').encode())
        self.buffer = b''
        while b'\r\n\r\n' not in self.buffer:
            self._receive()
        head, self.buffer = self.buffer.split(b'\r\n\r\n', 1)
        lines = head.decode().split('\r\n')
        assert lines[0].startswith('HTTP/1.1 101'), head.decode()
        headers = dict(line.split(': ', 1) for line in lines[1:])
        headers = {k.lower(): v for k, v in headers.items()}
        accept = base64.b64encode(hashlib.sha1(
            (key + '258EAFA5-E914-47DA-95CA-C5AB0DC85B11').encode()).digest()).decode()
        assert headers['sec-websocket-accept'] == accept
        self.protocol = headers['sec-websocket-protocol']

    def _receive(self):
        data = self.sock.recv(65536)
        if not data:
            raise EOFError('server closed the connection')
        self.buffer += data

    def _take(self, size: int) -> bytes:
        while len(self.buffer) < size:
            self._receive()
        out, self.buffer = self.buffer[:size], self.buffer[size:]
        return out

    def _send(self, opcode: int, payload: bytes):
        size = len(payload)
        if size < 126:
            header = struct.pack('!BB', 0x80 | opcode, 0x80 | size)
        elif size < 65536:
            header = struct.pack('!BBH', 0x80 | opcode, 0x80 | 126, size)
        else:
            header = struct.pack('!BBQ', 0x80 | opcode, 0x80 | 127, size)
        mask = os.urandom(4)  # clients mask every frame
        self.sock.sendall(header + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload)))

    def send_json(self, message: dict):
        """Send a text frame."""
        self._send(0x1, json.dumps(message).encode())

    def receive(self):
        """Return the next data message: ('text', dict) or ('binary', bytes)."""
        opcode, payload = None, b''
        while True:
            first, second = self._take(2)
            size = second & 0x7F
            if size == 126:
                size, = struct.unpack('!H', self._take(2))
            elif size == 127:
                size, = struct.unpack('!Q', self._take(8))
            data = self._take(size)
            frame_opcode = first & 0x0F
            if frame_opcode == 0x9:  # ping
                self._send(0xA, data)
                continue
            if frame_opcode == 0x8:
                raise EOFError('server closed the connection')
            if frame_opcode in (0x1, 0x2):
                opcode, payload = frame_opcode, data
            elif frame_opcode == 0x0:
                payload += data
            if first & 0x80 and opcode is not None:
                return ('text', json.loads(payload)) if opcode == 0x1 else ('binary', payload)

    def close(self):
        """Close the socket."""
        self.sock.close()


class Viewer:
    """A Foxglove client's view: server info, advertised channels, received messages."""

    def __init__(self, port: int):
        """Connect."""
        self.client = FoxgloveClient(port)
        self.server_info = None
        self.channels = {}        # channel id -> advertised channel
        self.subscriptions = {}   # subscription id -> channel id
        self.messages = []        # (topic, log time, payload)
        self.times = []

    def pump(self, until, timeout: float = 20.0):
        """Handle messages until until() is true."""
        deadline = time.monotonic() + timeout
        while not until():
            assert time.monotonic() < deadline, (
                f'timed out; channels {sorted(c["topic"] for c in self.channels.values())}, '
                f'messages on {sorted({m[0] for m in self.messages})}')
            kind, message = self.client.receive()
            if kind == 'text' and message['op'] == 'serverInfo':
                self.server_info = message
            elif kind == 'text' and message['op'] == 'advertise':
                self.channels.update({c['id']: c for c in message['channels']})
            elif kind == 'text' and message['op'] == 'unadvertise':
                for channel_id in message['channelIds']:
                    self.channels.pop(channel_id, None)
            elif kind == 'binary' and message[0] == 1:  # message data
                subscription, log_time = struct.unpack('<IQ', message[1:13])
                topic = self.channels[self.subscriptions[subscription]]['topic']
                self.messages.append((topic, log_time, message[13:]))
            elif kind == 'binary' and message[0] == 2:  # server time
                self.times.append(struct.unpack('<Q', message[1:9])[0])

    def channel(self, topic: str) -> dict:
        """Return the advertised channel of a topic, or None."""
        return next((c for c in self.channels.values() if c['topic'] == topic), None)

    def subscribe(self, *topics: str):
        """Subscribe to the channels of topics."""
        subscriptions = []
        for topic in topics:
            subscription_id = len(self.subscriptions) + 1
            self.subscriptions[subscription_id] = self.channel(topic)['id']
            subscriptions.append({'id': subscription_id, 'channelId': self.channel(topic)['id']})
        self.client.send_json({'op': 'subscribe', 'subscriptions': subscriptions})

    def received(self, topic: str) -> list:
        """Return the payloads received on a topic."""
        return [payload for t, _, payload in self.messages if t == topic]


def test_foxglove_bridge_serves_ros_topics_with_latched_ones_to_late_viewers(
        start_system, tmp_path):
    """Whitelisted topics are advertised with ROS schemas and relayed, latched ones late too."""
    system = start_system(str(write_launch(tmp_path, {
        'pkg': 'mecanum_bringup', 'exec': 'foxglove_bridge', 'name': 'foxglove_bridge',
        'param': [{'name': 'port', 'value': 0},
                  {'name': 'topic_whitelist', 'value': ['/scan', '/tf.*', '/simulation/.*']}]})))
    port = int(system.wait_for_line(
        r'\[foxglove_bridge\].*listening on ws://127\.0\.0\.1:(\d+) \(simulated time\)').group(1))
    for topic in ('/scan', '/tf_static', '/simulation/collisions'):
        system.wait_for_line(rf'\[foxglove_bridge\].*Advertised {topic} ', 30.0)

    viewer = Viewer(port)
    viewer.pump(lambda: viewer.channel('/scan') and viewer.channel('/tf_static'))
    assert viewer.server_info['name'] == 'mecanum foxglove_bridge'
    assert 'time' in viewer.server_info['capabilities']
    topics = {c['topic'] for c in viewer.channels.values()}
    assert '/ground_truth/odom' not in topics and '/odom' not in topics  # not whitelisted
    scan_channel = viewer.channel('/scan')
    assert (scan_channel['encoding'], scan_channel['schemaEncoding'],
            scan_channel['schemaName']) == ('cdr', 'ros2msg', 'sensor_msgs/msg/LaserScan')
    assert scan_channel['schema'] == message_definition('sensor_msgs/msg/LaserScan')

    viewer.subscribe('/scan', '/tf_static')
    viewer.pump(lambda: len(viewer.received('/scan')) >= 2 and viewer.received('/tf_static')
                and viewer.times)
    decode_scan = decoder_for('sensor_msgs/msg/LaserScan', scan_channel['schema'])
    scan = decode_scan(viewer.received('/scan')[-1])
    assert scan.header.frame_id == 'laser' and len(scan.ranges) == 360
    # Log times and the broadcast time are simulated time (well under 1000 s here).
    assert all(0 < log_time < 1000 * S for _, log_time, _ in viewer.messages)
    assert 0 < viewer.times[-1] < 1000 * S

    # The simulator published /tf_static once, at its start; a viewer connecting now
    # still gets it (the bridge keeps latched messages and re-sends them).
    late = Viewer(port)
    late.pump(lambda: late.channel('/tf_static'))
    late.subscribe('/tf_static')
    late.pump(lambda: late.received('/tf_static'))
    static_channel = late.channel('/tf_static')
    static = decoder_for('tf2_msgs/msg/TFMessage', static_channel['schema'])(
        late.received('/tf_static')[0])
    assert [(t.header.frame_id, t.child_frame_id) for t in static.transforms] == [
        ('base_link', 'laser')]
    assert late.client.protocol == 'foxglove.sdk.v1'
    viewer.client.close()
    late.client.close()
    assert system.stop() == 0
    assert 'Traceback' not in system.output()


@pytest.mark.parametrize('executable, parameters, message', [
    ('bag_recorder', ['output:={existing}'], r'parameter output: .*existing already exists'),
    ('bag_recorder', ['output:={new}', 'exclude:=([bad'],
     r'parameter exclude is not a valid regular expression'),
    ('foxglove_bridge', ["topic_whitelist:=['/scan', '(bad']"],
     r"parameter topic_whitelist: '\(bad' is not a valid regular expression"),
])
def test_bad_parameters_stop_the_node_with_one_clear_line(ros_env, tmp_path, executable,
                                                          parameters, message):
    """A bad parameter: exit code 2, one FATAL line naming it, no bag directory touched."""
    (tmp_path / 'existing').mkdir()
    command = [str(REPO / 'mecanum'), 'run', 'mecanum_bringup', executable, '--ros-args']
    for parameter in parameters:
        command += ['-p', parameter.format(existing=tmp_path / 'existing', new=tmp_path / 'new')]
    result = subprocess.run(command, env=ros_env, capture_output=True, text=True, timeout=60)
    fatal = [line for line in (result.stdout + result.stderr).splitlines() if 'FATAL' in line]
    assert result.returncode == 2, result.stderr
    assert len(fatal) == 1 and re.search(message, fatal[0]), fatal
    assert not (tmp_path / 'new').exists()
    assert list((tmp_path / 'existing').iterdir()) == []
