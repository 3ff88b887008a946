"""
Tests of the keyboard teleoperation's key logic: mecanum_control.teleop_keys.

Hand-worked cases (starting speeds 0.3 m/s and 1.0 rad/s, maxima 0.8 m/s and 2.5 rad/s).
The teleop_keyboard node itself is tested end to end in tests/test_teleop_keyboard_node.py.
"""

from hypothesis import given, strategies as st
from mecanum_control.teleop_keys import (
    apply_key, HELP_TEXT, MOVE_BINDINGS, QUIT_KEY, SPEED_BINDINGS, speeds_text, TeleopState,
    twist_from_state)
import pytest

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
