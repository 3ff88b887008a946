"""
Tests of the keyboard teleoperation: mecanum_control.teleop_keys and the node.

The key logic is tested with hand-worked cases (starting speeds 0.3 m/s and 1.0 rad/s,
maxima 0.8 m/s and 2.5 rad/s). The teleop_keyboard node is tested end to end in its
own process: its stdin is a real pseudo-terminal the test types into, and a real rclpy
subscription in a leased ROS domain records what it publishes on cmd_vel.
"""

import os
import signal
import subprocess
import sys
import termios
import threading
import time

from geometry_msgs.msg import Twist, TwistStamped
from hypothesis import given, strategies as st
from mecanum_bringup.isolation import isolated_environment, lease_domain_id
from mecanum_control.teleop_keys import (
    apply_key, HELP_TEXT, MOVE_BINDINGS, QUIT_KEY, SPEED_BINDINGS, speeds_text, TeleopState,
    twist_from_state)
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor

SPEED = 0.3
TURN = 1.0
MAX_SPEED = 0.8
MAX_TURN = 2.5


def start_state(**changes) -> TeleopState:
    """Return the stopped test state (0.3 m/s, 1.0 rad/s, maxima 0.8 / 2.5), with changes."""
    values = {'speed_m_s': SPEED, 'turn_rad_s': TURN, 'max_speed_m_s': MAX_SPEED,
              'max_turn_rad_s': MAX_TURN}
    values.update(changes)
    return TeleopState(**values)


def press(state: TeleopState, keys: str) -> TeleopState:
    """Return the state after pressing keys in order."""
    for key in keys:
        state, _ = apply_key(state, key)
    return state


# --- movement bindings --------------------------------------------------------------

@pytest.mark.parametrize('key, twist', [
    # u i o / j k l / m , .  (x forward, y left, wz counter-clockwise)
    ('u', (SPEED, 0.0, TURN)),
    ('i', (SPEED, 0.0, 0.0)),
    ('o', (SPEED, 0.0, -TURN)),
    ('j', (0.0, 0.0, TURN)),
    ('l', (0.0, 0.0, -TURN)),
    ('m', (-SPEED, 0.0, -TURN)),
    (',', (-SPEED, 0.0, 0.0)),
    ('.', (-SPEED, 0.0, TURN)),
    # Holonomic: U I O / J K L / M < >, translation only.
    ('U', (SPEED, SPEED, 0.0)),
    ('I', (SPEED, 0.0, 0.0)),
    ('O', (SPEED, -SPEED, 0.0)),
    ('J', (0.0, SPEED, 0.0)),
    ('L', (0.0, -SPEED, 0.0)),
    ('M', (-SPEED, SPEED, 0.0)),
    ('<', (-SPEED, 0.0, 0.0)),
    ('>', (-SPEED, -SPEED, 0.0)),
])
def test_movement_key_gives_its_direction(key, twist):
    """Each movement key from stop commands its twist at the current speeds."""
    state, recognised = apply_key(start_state(), key)
    assert recognised
    assert state.moving
    assert twist_from_state(state) == pytest.approx(twist)


def test_every_movement_binding_is_tested():
    """The table above covers all 16 bindings of teleop_twist_keyboard (less t/b)."""
    assert sorted(MOVE_BINDINGS) == sorted('uiojlm,.UIOJLM<>')


def test_holonomic_strafe_left_and_right():
    """J strafes left (+y), L strafes right (-y), neither moves forward nor turns."""
    assert twist_from_state(press(start_state(), 'J')) == (0.0, SPEED, 0.0)
    assert twist_from_state(press(start_state(), 'L')) == (0.0, -SPEED, 0.0)


def test_new_movement_key_replaces_the_direction():
    """Directions do not add up: the last movement key wins."""
    assert twist_from_state(press(start_state(), 'iJ')) == (0.0, SPEED, 0.0)


def test_stopped_state_commands_zero():
    """A fresh state does not move."""
    state = start_state()
    assert not state.moving
    assert twist_from_state(state) == (0.0, 0.0, 0.0)


# --- stop keys and unknown keys --------------------------------------------------------

@pytest.mark.parametrize('key', ['k', 'K', ' ', QUIT_KEY])
def test_stop_keys_stop_and_keep_speeds(key):
    """k, K (holonomic centre), space and Ctrl-C stop; the speeds stay."""
    state, recognised = apply_key(press(start_state(), 'qU'), key)
    assert recognised
    assert not state.moving
    assert twist_from_state(state) == (0.0, 0.0, 0.0)
    assert (state.speed_m_s, state.turn_rad_s) == pytest.approx((0.33, 1.1))


@pytest.mark.parametrize('key', ['a', 't', 'b', '\x1b', '\r', 'é'])
def test_unknown_key_is_not_recognised_and_stops(key):
    """Like teleop_twist_keyboard, 'anything else' stops; it is reported as not bound."""
    state, recognised = apply_key(press(start_state(), 'u'), key)
    assert not recognised
    assert twist_from_state(state) == (0.0, 0.0, 0.0)
    assert (state.speed_m_s, state.turn_rad_s) == (SPEED, TURN)


def test_apply_key_does_not_change_its_argument():
    """States are values: apply_key returns a new one."""
    state = start_state()
    apply_key(state, 'i')
    apply_key(state, 'q')
    assert state == start_state()


# --- speed keys -----------------------------------------------------------------------

@pytest.mark.parametrize('key, speed, turn', [
    ('q', 0.33, 1.1),    # both +10 %
    ('z', 0.27, 0.9),    # both -10 %
    ('w', 0.33, 1.0),    # linear only
    ('x', 0.27, 1.0),
    ('e', 0.3, 1.1),     # angular only
    ('c', 0.3, 0.9),
])
def test_speed_keys_scale_by_ten_percent(key, speed, turn):
    """q/z both speeds, w/x linear only, e/c angular only, by 10 %."""
    state, recognised = apply_key(start_state(), key)
    assert recognised
    assert (state.speed_m_s, state.turn_rad_s) == pytest.approx((speed, turn))


def test_speed_key_keeps_moving_at_the_new_speed():
    """Forward, then q: still forward, 10 % faster; turning left, then e: turns faster."""
    assert twist_from_state(press(start_state(), 'iq')) == pytest.approx((0.33, 0.0, 0.0))
    assert twist_from_state(press(start_state(), 'je')) == pytest.approx((0.0, 0.0, 1.1))


def test_q_clamps_at_the_maxima():
    """
    Speeds never exceed the maxima given at construction.

    0.3 * 1.1**10 = 0.778 and 0.3 * 1.1**11 = 0.856 > 0.8; 1.0 * 1.1**9 = 2.36 and
    1.0 * 1.1**10 = 2.59 > 2.5.
    """
    state = press(start_state(), 'q' * 9)
    assert (state.speed_m_s, state.turn_rad_s) == pytest.approx((0.3 * 1.1 ** 9, 1.1 ** 9))
    state = press(state, 'q')
    assert state.speed_m_s == pytest.approx(0.3 * 1.1 ** 10)
    assert state.turn_rad_s == MAX_TURN
    state = press(state, 'q')
    assert (state.speed_m_s, state.turn_rad_s) == (MAX_SPEED, MAX_TURN)
    state = press(state, 'qqqwe' * 5 + 'U')
    assert (state.speed_m_s, state.turn_rad_s) == (MAX_SPEED, MAX_TURN)
    assert twist_from_state(state) == (MAX_SPEED, MAX_SPEED, 0.0)


def test_z_after_clamping_goes_down_from_the_maximum():
    """At the maximum, z gives 90 % of the maximum."""
    state = press(start_state(), 'q' * 20 + 'z')
    assert (state.speed_m_s, state.turn_rad_s) == pytest.approx((0.72, 2.25))


def test_many_z_stop_at_one_percent_of_the_maxima():
    """The speeds stay above zero so that q can bring them back."""
    state = press(start_state(), 'z' * 200)
    assert (state.speed_m_s, state.turn_rad_s) == pytest.approx((0.008, 0.025))
    assert press(state, 'q').speed_m_s == pytest.approx(0.0088)


@given(st.text(alphabet='uiojklm,.UIOJKLM<> qzwxecab\x03', max_size=60))
def test_any_key_sequence_stays_within_the_maxima(keys):
    """Whatever is typed, every twist component is within the maxima."""
    state = start_state()
    for key in keys:
        state, _ = apply_key(state, key)
        vx, vy, wz = twist_from_state(state)
        assert abs(vx) <= MAX_SPEED and abs(vy) <= MAX_SPEED and abs(wz) <= MAX_TURN
        assert 0 < state.speed_m_s <= MAX_SPEED and 0 < state.turn_rad_s <= MAX_TURN


def test_speed_bindings_are_those_of_teleop_twist_keyboard():
    """q/z, w/x, e/c and nothing else change the speeds."""
    assert sorted(SPEED_BINDINGS) == sorted('qzwxec')


# --- construction ---------------------------------------------------------------------

def test_initial_clamps_the_speeds_to_the_maxima():
    """Starting speeds above the maxima start at the maxima."""
    state = TeleopState.initial(1.0, 3.0, MAX_SPEED, MAX_TURN)
    assert (state.speed_m_s, state.turn_rad_s) == (MAX_SPEED, MAX_TURN)
    assert not state.moving


@pytest.mark.parametrize('args, name', [
    ((0.0, TURN, MAX_SPEED, MAX_TURN), 'speed_m_s'),
    ((SPEED, -1.0, MAX_SPEED, MAX_TURN), 'turn_rad_s'),
    ((SPEED, TURN, float('nan'), MAX_TURN), 'max_speed_m_s'),
    ((SPEED, TURN, MAX_SPEED, float('inf')), 'max_turn_rad_s'),
])
def test_initial_rejects_bad_values_naming_them(args, name):
    """Values must be finite and > 0; the error names the parameter."""
    with pytest.raises(ValueError, match=name):
        TeleopState.initial(*args)


def test_state_refuses_speeds_beyond_the_maxima():
    """The invariant speed <= max holds for every state."""
    with pytest.raises(ValueError, match='speed_m_s'):
        start_state(speed_m_s=0.9)
    with pytest.raises(ValueError, match='turn_rad_s'):
        start_state(turn_rad_s=2.6)
    with pytest.raises(ValueError, match='y'):
        start_state(y=2)


# --- texts ----------------------------------------------------------------------------

def test_help_text_shows_both_key_grids():
    """The help text shows teleop_twist_keyboard's grids and how to quit."""
    for line in ('u    i    o', 'j    k    l', 'm    ,    .',
                 'U    I    O', 'J    K    L', 'M    <    >', 'CTRL-C to quit'):
        assert line in HELP_TEXT


def test_speeds_text_marks_the_maxima():
    """The 'currently:' line gives both speeds and says when one is at its maximum."""
    assert speeds_text(start_state()) == 'currently:\tspeed 0.3 m/s\tturn 1 rad/s'
    text = speeds_text(press(start_state(), 'w' * 20))
    assert text == 'currently:\tspeed 0.8 m/s (max)\tturn 1 rad/s'


# --- the node, end to end --------------------------------------------------------------

MODULE = 'mecanum_control.teleop_keyboard'


@pytest.fixture(name='ros_domain')
def ros_domain_fixture(monkeypatch):
    """Lease a ROS domain; discovery stays on localhost, also for this process."""
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    with lease_domain_id() as lease:
        yield lease.domain_id


class CmdVelRecorder:
    """Records cmd_vel in the given domain from a node spun in a background thread."""

    def __init__(self, domain_id: int, msg_type):
        """Start the recorder node."""
        self.messages = []
        self._lock = threading.Lock()
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node('teleop_test_recorder', context=self.context)
        self.node.create_subscription(msg_type, 'cmd_vel_teleop', self._on_message, 100)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self):
        while self.context.ok():
            try:
                self.executor.spin_once(timeout_sec=0.05)
            except Exception:  # noqa: B902 - shutting down mid-spin
                if self.context.ok():
                    raise

    def _on_message(self, msg):
        with self._lock:
            self.messages.append((time.monotonic(), msg))

    def since(self, start: float) -> list:
        """Return (time, message) pairs received at or after monotonic time start."""
        with self._lock:
            return [(when, msg) for when, msg in self.messages if when >= start]

    def close(self):
        """Stop the recorder node."""
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
        self._thread.join(timeout=5)


def twist_of(msg) -> tuple:
    """(vx, vy, wz) of a Twist or TwistStamped."""
    twist = msg.twist if isinstance(msg, TwistStamped) else msg
    return (twist.linear.x, twist.linear.y, twist.angular.z)


class TeleopProcess:
    """The teleop_keyboard node in its own process, its stdin a pseudo-terminal."""

    def __init__(self, domain_id: int, *parameters: str):
        """Start the node with parameters (name:=value)."""
        self.master, self.slave = os.openpty()
        self.terminal_settings = termios.tcgetattr(self.slave)
        ros_args = ['--ros-args'] + [arg for p in parameters for arg in ('-p', p)]
        self.process = subprocess.Popen(
            [sys.executable, '-m', MODULE, *ros_args], stdin=self.slave,
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            env=isolated_environment(os.environ, domain_id), start_new_session=True)
        self.lines = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self):
        for line in self.process.stdout:
            self.lines.append(line.rstrip('\n'))

    def output(self) -> str:
        """Everything the node printed so far."""
        return '\n'.join(self.lines)

    def wait_for_output(self, text: str, timeout: float = 15.0) -> None:
        """Wait until the node printed text (it prints the help once in raw mode)."""
        deadline = time.monotonic() + timeout
        while text not in self.output():
            assert self.process.poll() is None, f'node exited:\n{self.output()}'
            assert time.monotonic() < deadline, f'no {text!r} in:\n{self.output()}'
            time.sleep(0.02)

    def type_keys(self, keys: str) -> None:
        """Type keys on the node's terminal."""
        os.write(self.master, keys.encode())

    def hold(self, key: str, recorder: CmdVelRecorder, twist: tuple,
             timeout: float = 15.0) -> float:
        """
        Type key every 50 ms, as a held key repeats, until twist is received.

        Return the monotonic time of the last key typed. Holding covers the DDS
        discovery time: twists published before the subscription matched are lost.
        """
        start = time.monotonic()
        while time.monotonic() - start < timeout:
            self.type_keys(key)
            typed = time.monotonic()
            time.sleep(0.05)
            if any(twist_of(msg) == pytest.approx(twist) for _, msg in recorder.since(start)):
                return typed
        raise AssertionError(f'holding {key!r} did not give {twist}:\n{self.output()}')

    def terminal_restored(self) -> bool:
        """Whether the terminal settings are those from before the node started."""
        return termios.tcgetattr(self.slave) == self.terminal_settings

    def close(self) -> None:
        """Kill the node if it still runs; close the terminal."""
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait(timeout=5)
        os.close(self.master)
        os.close(self.slave)


@pytest.mark.integration
def test_node_without_terminal_exits_2_with_a_clear_message(ros_domain):
    """With stdin not a TTY (here /dev/null) the node refuses to start: exit code 2."""
    result = subprocess.run(
        [sys.executable, '-m', MODULE], stdin=subprocess.DEVNULL, capture_output=True,
        text=True, timeout=30, env=isolated_environment(os.environ, ros_domain))
    assert result.returncode == 2
    assert 'teleop_keyboard needs an interactive terminal' in result.stderr
    assert './mecanum run mecanum_control teleop_keyboard' in result.stderr


@pytest.mark.integration
def test_node_keys_repeat_timeout_and_ctrl_c(ros_domain):
    """
    Typed keys become cmd_vel Twists; the twist repeats, times out, and Ctrl-C stops.

    J strafes left, L right; with no key for key_timeout_s (0.6 s) a zero twist follows
    the repeated ones and then the node is quiet; q then I is 10 % faster forward;
    Ctrl-C publishes zero, exits 0 and restores the terminal settings.
    """
    recorder = CmdVelRecorder(ros_domain, Twist)
    teleop = TeleopProcess(ros_domain, 'key_timeout_s:=0.6', 'repeat_rate_hz:=10.0')
    try:
        teleop.wait_for_output('currently:\tspeed 0.3 m/s\tturn 1 rad/s')
        assert 'M    <    >' in teleop.output()
        teleop.hold('J', recorder, (0.0, 0.3, 0.0))
        last_key = teleop.hold('L', recorder, (0.0, -0.3, 0.0))
        deadline = last_key + 5.0
        while not any(twist_of(m) == (0.0, 0.0, 0.0) for _, m in recorder.since(last_key)):
            assert time.monotonic() < deadline, 'no zero twist after the key timeout'
            time.sleep(0.02)
        after = recorder.since(last_key)
        stop_time = next(when for when, m in after if twist_of(m) == (0.0, 0.0, 0.0))
        repeats = [when for when, m in after if when < stop_time]
        assert 0.5 < stop_time - last_key < 1.5
        assert all(twist_of(m) == pytest.approx((0.0, -0.3, 0.0))
                   for when, m in after if when < stop_time)
        assert len([when for when in repeats if when > last_key + 0.15]) >= 2
        time.sleep(0.4)
        assert len(recorder.since(stop_time + 0.01)) == 0, 'twists after stopping'

        teleop.type_keys('q')
        teleop.hold('I', recorder, (0.33, 0.0, 0.0))
        assert 'currently:\tspeed 0.33 m/s\tturn 1.1 rad/s' in teleop.output()
        quit_time = time.monotonic()
        teleop.type_keys(QUIT_KEY)
        assert teleop.process.wait(timeout=10) == 0
        time.sleep(0.2)
        assert twist_of(recorder.since(quit_time)[-1][1]) == (0.0, 0.0, 0.0)
        assert teleop.terminal_restored()
    finally:
        teleop.close()
        recorder.close()


@pytest.mark.integration
def test_node_stamped_and_sigterm_while_moving(ros_domain):
    """
    With stamped:=true it publishes TwistStamped in base_link; SIGTERM publishes zero.

    Holding U moves diagonally forward-left; SIGTERM while moving (and within the
    key timeout) still ends with a zero twist, exit code 0 and the terminal restored.
    """
    recorder = CmdVelRecorder(ros_domain, TwistStamped)
    teleop = TeleopProcess(ros_domain, 'stamped:=true', 'speed_m_s:=0.2')
    try:
        teleop.wait_for_output('currently:\tspeed 0.2 m/s')
        teleop.hold('U', recorder, (0.2, 0.2, 0.0))
        moving = [m for _, m in recorder.since(0.0) if twist_of(m) != (0.0, 0.0, 0.0)]
        assert {m.header.frame_id for m in moving} == {'base_link'}
        assert all(m.header.stamp.sec > 0 for m in moving)
        signal_time = time.monotonic()
        teleop.process.send_signal(signal.SIGTERM)
        assert teleop.process.wait(timeout=10) == 0
        time.sleep(0.2)
        assert twist_of(recorder.since(signal_time)[-1][1]) == (0.0, 0.0, 0.0)
        assert teleop.terminal_restored()
    finally:
        teleop.close()
        recorder.close()
