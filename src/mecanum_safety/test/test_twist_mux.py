"""Hand-worked tests of mecanum_safety.twist_mux (ros-teleop/twist_mux's rules)."""

import functools
import math
from pathlib import Path

from mecanum_control.command_limits import AxisLimits, limit_scale, TwistLimits
from mecanum_control.kinematics import inverse_kinematics, MecanumGeometry
from mecanum_control.robot_config import default_config_path, load_robot_config
from mecanum_safety.twist_mux import (
    Entry, non_finite_component, parse_entries, Step, TwistMux)
import pytest
import yaml

PACKAGE = Path(__file__).resolve().parents[1]
CONFIG = PACKAGE / 'config' / 'twist_mux.yaml'
GO = (0.3, 0.0, 0.0, 0.0, 0.0, 0.2)
STOP = (0.0,) * 6
NAV = Entry('navigation', 'cmd_vel_smoothed', 0.5, 10)
TELEOP = Entry('teleop', 'cmd_vel_teleop', 0.5, 95)
JOY = Entry('joystick', 'cmd_vel_joy', 0.5, 100)
E_STOP = Entry('e_stop', 'emergency_stop', 0.0, 255)
LATCH = Entry('e_stop_latched', 'emergency_stop_latched', 0.0, 255)
ROBOT = load_robot_config(default_config_path())
#: The robot's limits as twist_mux_node applies them (motor_params.yaml).
ROBOT_LIMIT = functools.partial(
    limit_scale, limits=TwistLimits.from_config(ROBOT), geometry=ROBOT.geometry,
    max_wheel_speed_rad_s=ROBOT.max_wheel_speed_rad_s)


def flatten(tree, prefix=''):
    """Return a YAML mapping as ROS 2 parameters {'a.b.c': value} (as rcl reads it)."""
    flat = {}
    for key, value in tree.items():
        name = f'{prefix}{key}'
        if isinstance(value, dict):
            flat.update(flatten(value, name + '.'))
        else:
            flat[name] = value
    return flat


def mux(*topics, locks=(), limit=None):
    """Return a TwistMux of the given entries."""
    return TwistMux(list(topics), list(locks), limit=limit)


# -- parameters ---------------------------------------------------------------------------

def test_the_project_config_parses_in_twist_mux_order():
    """config/twist_mux.yaml: six topics sorted by name, two locks, no warnings."""
    params = flatten(yaml.safe_load(CONFIG.read_text())['twist_mux']['ros__parameters'])
    topics, warnings = parse_entries('topics', params)
    locks, lock_warnings = parse_entries('locks', params)
    assert warnings == lock_warnings == []
    assert topics == [
        Entry('external', 'cmd_vel', 0.5, 90),
        Entry('joystick', 'cmd_vel_joy', 0.5, 100),
        Entry('navigation', 'cmd_vel_smoothed', 0.5, 10),
        Entry('scenario', 'cmd_vel_scenario', 0.5, 80),
        Entry('teleop_keyboard', 'cmd_vel_teleop', 0.5, 95),
        Entry('text_commands', 'cmd_vel_text', 0.5, 50),
    ]
    assert locks == [E_STOP, LATCH]
    assert params['use_stamped'] is False
    TwistMux(topics, locks)   # valid as a whole


def test_twist_mux_upstream_example_files_parse_unchanged():
    """twist_mux's own config/twist_mux_topics.yaml and twist_mux_locks.yaml (abridged)."""
    text = """
twist_mux:
  ros__parameters:
    topics:
      navigation:
        topic   : nav_vel
        timeout : 0.5
        priority: 10
      joystick:
        topic   : joy_vel
        timeout : 0.5
        priority: 100
      keyboard:
        topic   : key_vel
        timeout : 0.5
        priority: 90
    locks:
      pause:
        topic   : pause_navigation
        timeout : 0.0
        priority: 100
      loop_closure:
        topic   : stop_closing_loop
        timeout : 0.0
        priority: 200
"""
    params = flatten(yaml.safe_load(text)['twist_mux']['ros__parameters'])
    topics, _ = parse_entries('topics', params)
    locks, _ = parse_entries('locks', params)
    assert [t.name for t in topics] == ['joystick', 'keyboard', 'navigation']
    assert [(lk.name, lk.priority) for lk in locks] == [('loop_closure', 200), ('pause', 100)]
    core = TwistMux(topics, locks)
    # pause (100) masks keyboard (90) and navigation (10) but not joystick (100).
    core.on_lock('pause', True, 0.0)
    assert core.on_twist('keyboard', GO, 0.1).forward is False
    assert core.on_twist('joystick', GO, 0.1).forward is True


def test_order_is_by_full_parameter_name_as_rclcpp_lists_them():
    """'a' sorts before 'a_b' ('a.' < 'a_'), as the prefixes of rclcpp's sorted map."""
    params = {'topics.a_b.topic': 't2', 'topics.a_b.timeout': 0.5, 'topics.a_b.priority': 5,
              'topics.a.topic': 't1', 'topics.a.timeout': 1, 'topics.a.priority': 5.0,
              'use_sim_time': True}
    topics, warnings = parse_entries('topics', params)
    assert topics == [Entry('a', 't1', 1.0, 5), Entry('a_b', 't2', 0.5, 5)]
    assert isinstance(topics[0].timeout_s, float) and isinstance(topics[0].priority, int)
    assert warnings == []
    assert parse_entries('locks', params) == ([], [])


def entry_params(**changes):
    """Return the parameters of one valid entry 'nav' with changes (None: key removed)."""
    params = {'topics.nav.topic': 'cmd_vel_smoothed', 'topics.nav.timeout': 0.5,
              'topics.nav.priority': 10}
    for key, value in changes.items():
        if value is None:
            del params[f'topics.nav.{key}']
        else:
            params[f'topics.nav.{key}'] = value
    return params


@pytest.mark.parametrize('changes, message', [
    ({'topic': None}, r'parameter topics\.nav\.topic is missing'),
    ({'timeout': None}, r'parameter topics\.nav\.timeout is missing'),
    ({'priority': None}, r'parameter topics\.nav\.priority is missing'),
    ({'topic': ''}, r'parameter topics\.nav\.topic must be a non-empty topic name'),
    ({'topic': 5}, r'parameter topics\.nav\.topic must be a non-empty topic name'),
    ({'timeout': -0.1}, r'parameter topics\.nav\.timeout must be finite and >= 0'),
    ({'timeout': math.inf}, r'parameter topics\.nav\.timeout must be finite and >= 0'),
    ({'timeout': math.nan}, r'parameter topics\.nav\.timeout must be finite and >= 0'),
    ({'timeout': 'fast'}, r'parameter topics\.nav\.timeout must be a number'),
    ({'timeout': True}, r'parameter topics\.nav\.timeout must be a number'),
    ({'priority': 256}, r'parameter topics\.nav\.priority must be within 0-255, got 256'),
    ({'priority': -1}, r'parameter topics\.nav\.priority must be within 0-255, got -1'),
    ({'priority': 10.5}, r'parameter topics\.nav\.priority must be an integer 0-255'),
    ({'priority': math.nan}, r'parameter topics\.nav\.priority must be an integer 0-255'),
    ({'priority': True}, r'parameter topics\.nav\.priority must be an integer 0-255'),
])
def test_bad_entries_are_refused_naming_the_parameter(changes, message):
    """Each missing or bad key raises ValueError naming the full parameter."""
    with pytest.raises(ValueError, match=message):
        parse_entries('topics', entry_params(**changes))


def test_malformed_groups_are_refused():
    """A value for topics, or for an entry, is refused naming the parameter."""
    with pytest.raises(ValueError, match=r'parameter topics must be a map of entries'):
        parse_entries('topics', {'topics': ['cmd_vel']})
    with pytest.raises(ValueError, match=r'parameter topics\.nav must be a map with topic'):
        parse_entries('topics', {'topics.nav': 'cmd_vel'})


def test_unknown_keys_and_priority_zero_give_warnings():
    """twist_mux ignores unknown keys and never selects priority 0: warned, not refused."""
    params = entry_params(stamped=True, priority=0)
    topics, warnings = parse_entries('topics', params)
    assert topics == [Entry('nav', 'cmd_vel_smoothed', 0.5, 0)]
    assert len(warnings) == 2
    assert 'topics.nav.stamped ignored' in warnings[0]
    assert 'topics.nav.priority is 0' in warnings[1]
    lock_params = {'locks.l.topic': 'x', 'locks.l.timeout': 0, 'locks.l.priority': 0}
    assert 'masks nothing' in parse_entries('locks', lock_params)[1][0]


def test_configuration_checks():
    """No topics, two entries on one topic (also across groups, also resolved), bad names."""
    with pytest.raises(ValueError, match=r'parameter topics is empty'):
        TwistMux([], [E_STOP])
    with pytest.raises(ValueError, match=r'parameters topics\.navigation\.topic and '
                                         r'topics\.other\.topic name the same topic '
                                         r'cmd_vel_smoothed'):
        TwistMux([NAV, Entry('other', 'cmd_vel_smoothed', 0.5, 20)])
    with pytest.raises(ValueError, match=r'topics\.navigation\.topic and locks\.l\.topic'):
        TwistMux([NAV], [Entry('l', 'cmd_vel_smoothed', 0.0, 50)])
    with pytest.raises(ValueError, match=r'topics\.navigation\.topic and '
                                         r'topics\.abs\.topic name the same topic '
                                         r'/cmd_vel_smoothed'):
        TwistMux([NAV, Entry('abs', '/cmd_vel_smoothed', 0.5, 20)],
                 resolve=lambda t: t if t.startswith('/') else '/' + t)

    def refuse(topic):
        raise ValueError(f'invalid {topic}')
    with pytest.raises(ValueError, match=r'parameter topics\.navigation\.topic is not a '
                                         r'valid topic name: invalid cmd_vel_smoothed'):
        TwistMux([NAV], resolve=refuse)
    with pytest.raises(ValueError, match='name twice'):
        TwistMux([NAV, NAV])


# -- selection ----------------------------------------------------------------------------

def test_a_single_source_passes_through_and_starts_silent():
    """Before any twist: state 'none'; each twist of the only live source is forwarded."""
    core = mux(NAV)
    assert core.update(0.0) == Step(forward=False, stop=False, state='none', changed=True)
    assert core.update(0.05) == Step(forward=False, stop=False, state='none', changed=False)
    assert core.on_twist('navigation', GO, 0.1) == Step(True, False, 'navigation', True)
    assert core.on_twist('navigation', GO, 0.2) == Step(True, False, 'navigation', False)


def test_highest_live_priority_wins_and_lower_ones_are_dropped():
    """Navigation (10) driving; teleop (95) speaks: teleop forwarded, navigation dropped."""
    core = mux(NAV, TELEOP)
    assert core.on_twist('navigation', GO, 1.0).forward
    step = core.on_twist('teleop', GO, 1.1)
    assert step == Step(True, False, 'teleop', True)
    assert core.on_twist('navigation', GO, 1.2) == Step(False, False, 'teleop', False)
    assert core.topic_status('navigation', 1.2) == 'live'
    assert core.topic_status('teleop', 1.2) == 'selected'


def test_timeout_expiry_hands_back_to_the_next_live_source_without_a_zero():
    """Teleop last at 1.1 s, timeout 0.5: live at 1.6 (== timeout), gone at 1.61."""
    core = mux(NAV, TELEOP)
    core.on_twist('teleop', GO, 1.1)
    for t in (1.2, 1.3, 1.4, 1.5):
        core.on_twist('navigation', GO, t)
    assert core.update(1.6) == Step(False, False, 'teleop', False)
    assert core.on_twist('navigation', GO, 1.6).forward is False
    # 1.61: teleop 0.51 s old -> expired; navigation (1.6) live: selected, no zero.
    assert core.update(1.61) == Step(False, False, 'navigation', True)
    assert core.on_twist('navigation', GO, 1.65) == Step(True, False, 'navigation', False)
    assert core.topic_status('teleop', 1.65) == 'silent'


def test_the_last_source_going_silent_sends_one_zero_then_nothing():
    """Navigation last at 2.0 s: at 2.55 one stop; later updates stop no more."""
    core = mux(NAV, TELEOP)
    core.on_twist('navigation', GO, 2.0)
    assert core.update(2.5) == Step(False, False, 'navigation', False)
    assert core.update(2.55) == Step(forward=False, stop=True, state='none', changed=True)
    for t in (2.6, 3.0, 10.0):
        assert core.update(t) == Step(False, False, 'none', False)
    # A new twist starts over.
    assert core.on_twist('navigation', GO, 10.1) == Step(True, False, 'navigation', True)


def test_a_zero_timeout_topic_never_expires_once_it_spoke():
    """A timeout 0 (twist_mux: never expires): silent before its first twist, then live."""
    keep = Entry('keep', 'keep_vel', 0.0, 20)
    core = mux(NAV, keep)
    assert not core.topic_live('keep', 0.0)
    core.on_twist('keep', GO, 1.0)
    assert core.topic_live('keep', 1e6)
    assert core.on_twist('navigation', GO, 1e6).forward is False


def test_ties_go_to_the_first_entry_in_twist_mux_order():
    """Two topics of priority 100: the first listed wins while both are live."""
    tablet = Entry('tablet', 'tab_vel', 0.5, 100)
    core = mux(JOY, tablet)            # joystick sorts before tablet
    assert core.on_twist('tablet', GO, 0.0).forward      # alone: selected
    assert core.on_twist('joystick', GO, 0.1).forward    # tie: the first one wins
    assert core.on_twist('tablet', GO, 0.2).forward is False
    assert core.update(0.61) == Step(False, False, 'tablet', True)   # joystick expired


def test_priority_zero_is_never_selected_as_in_twist_mux():
    """twist_mux's selection starts at priority 0 with a strict '<'."""
    core = mux(Entry('zero', 'zero_vel', 0.5, 0))
    assert core.on_twist('zero', GO, 0.0) == Step(False, False, 'none', True)


# -- locks --------------------------------------------------------------------------------

def test_an_engaged_lock_masks_lower_priorities_and_sends_one_zero():
    """e_stop (255) true while teleop drives: one stop, 'locked by e_stop', all dropped."""
    core = mux(NAV, TELEOP, locks=[E_STOP])
    core.on_twist('teleop', GO, 0.0)
    assert core.on_lock('e_stop', True, 0.1) == Step(False, True, 'locked by e_stop', True)
    assert core.on_twist('teleop', GO, 0.15) == Step(False, False, 'locked by e_stop', False)
    assert core.on_twist('navigation', GO, 0.2).forward is False
    assert core.topic_status('teleop', 0.2) == 'masked'
    assert core.lock_status('e_stop', 0.2) == 'engaged'
    assert core.lock_priority(0.2) == 255
    # Released: teleop, masked while it kept driving, is held until a new command.
    assert core.on_lock('e_stop', False, 0.3) == Step(False, False, 'held teleop', True)
    assert core.on_twist('teleop', GO, 0.35) == Step(False, False, 'held teleop', False)


def test_a_lock_masks_only_strictly_lower_priorities():
    """A lock of priority 95 masks navigation (10), not teleop (95)."""
    pause = Entry('pause', 'pause', 0.0, 95)
    core = mux(NAV, TELEOP, locks=[pause])
    assert core.on_lock('pause', True, 0.0) == Step(False, False, 'locked by pause', True)
    assert core.on_twist('navigation', GO, 0.1) == Step(False, False, 'locked by pause', False)
    assert core.on_twist('teleop', GO, 0.2) == Step(True, False, 'teleop', True)


def test_the_highest_engaged_lock_counts():
    """Two engaged locks (50, 200): the lock priority is 200, the state names it."""
    low, high = Entry('low', 'low_lock', 0.0, 50), Entry('high', 'high_lock', 0.0, 200)
    core = mux(NAV, locks=[low, high])
    core.on_lock('low', True, 0.0)
    core.on_lock('high', True, 0.0)
    assert core.lock_priority(0.0) == 200
    assert core.state_at(0.0) == 'locked by high'
    core.on_lock('high', False, 0.1)
    assert core.state_at(0.1) == 'locked by low'


def test_a_lock_with_a_timeout_engages_when_its_publisher_goes_quiet():
    """Lock timeout 1.0: engaged until the first message, free while fed, engaged 1 s after."""
    alive = Entry('alive', 'heartbeat', 1.0, 100)
    core = mux(NAV, locks=[alive])
    assert core.update(0.0).state == 'locked by alive'
    assert core.lock_status('alive', 0.0) == 'engaged (timed out)'
    assert core.on_lock('alive', False, 0.5).state == 'none'
    assert core.on_twist('navigation', GO, 1.0).forward
    assert core.on_twist('navigation', GO, 1.5).forward      # lock 1.0 s old: still free
    assert core.update(1.51) == Step(False, True, 'locked by alive', True)
    # Back: navigation, masked while live, must send a new command (a zero) first.
    assert core.on_lock('alive', False, 1.6).state == 'held navigation'
    assert core.on_twist('navigation', STOP, 1.7) == Step(True, False, 'navigation', True)


def test_a_zero_timeout_lock_only_counts_its_value():
    """Lock timeout 0: free before any message and however old its last false is."""
    core = mux(NAV, locks=[E_STOP])
    assert core.lock_status('e_stop', 0.0) == 'free'
    core.on_lock('e_stop', False, 0.0)
    assert core.on_twist('navigation', GO, 100.0).forward


# -- non-finite twists and time -----------------------------------------------------------

def test_non_finite_twists_are_rejected_and_silence_their_source():
    """A NaN from the only source: not forwarded, one stop; next finite twist resumes."""
    core = mux(NAV, TELEOP)
    core.on_twist('navigation', GO, 0.0)
    bad = (0.3, 0.0, 0.0, 0.0, 0.0, math.nan)
    assert core.on_twist('navigation', bad, 0.1) == Step(False, True, 'none', True)
    assert core.on_twist('navigation', bad, 0.2) == Step(False, False, 'none', False)
    assert core.on_twist('navigation', GO, 0.3) == Step(True, False, 'navigation', True)
    # An inf from teleop while navigation is live: navigation takes over, no stop.
    core.on_twist('teleop', GO, 0.35)
    assert core.on_twist('teleop', (math.inf,) + GO[1:], 0.4) == Step(
        False, False, 'navigation', True)


def test_non_finite_component_names_the_first_bad_one():
    """The warning text names the component."""
    assert non_finite_component(GO) is None
    assert non_finite_component((0, 0, math.inf, math.nan, 0, 0)) == 'linear.z is inf'
    assert non_finite_component((0, 0, 0, 0, 0, -math.inf)) == 'angular.z is -inf'


def test_a_clock_that_jumps_back_expires_the_inputs():
    """Stamped at 100 s, the clock now reads 1 s (restarted simulation): silent, stop."""
    core = mux(NAV)
    core.on_twist('navigation', GO, 100.0)
    assert core.update(1.0) == Step(False, True, 'none', True)


# -- the robot's limits (issue 31: the chain judges the twist the wheels will run) -------

def test_the_command_chain_launch_gives_twist_mux_the_robots_limits():
    """command_chain.launch.yaml passes motor_params.yaml to twist_mux (one source)."""
    launch = yaml.safe_load((PACKAGE / 'launch/command_chain.launch.yaml').read_text())
    nodes = [item['node'] for item in launch['launch'] if 'node' in item]
    mux_node = next(node for node in nodes if node['name'] == 'twist_mux')
    files = [param['from'] for param in mux_node['param'] if 'from' in param]
    assert '$(find-pkg-share mecanum_control)/config/motor_params.yaml' in files


def test_an_over_limit_diagonal_is_scaled_as_a_whole():
    """
    (0.8, 0.8, 0) with 0.5 m/s per axis -> (0.5, 0.5, 0): factor 0.625, still 45 deg.

    Its wheels then need (0.5 + 0.5) / 0.05 = 20 rad/s; with a 16 rad/s limit the
    factor becomes 0.625 * 16 / 20 = 0.5: (0.4, 0.4, 0).
    """
    geometry = MecanumGeometry(0.05, 0.10, 0.15)
    half = TwistLimits(AxisLimits(0.5, 1.0), AxisLimits(0.5, 1.0), AxisLimits(2.0, 4.0))
    diagonal = (0.8, 0.8, 0.0, 0.0, 0.0, 0.0)
    core = mux(NAV, limit=functools.partial(limit_scale, limits=half, geometry=geometry,
                                            max_wheel_speed_rad_s=30.0))
    step = core.on_twist('navigation', diagonal, 0.0)
    assert step.forward and step.scale == pytest.approx(0.625)
    core = mux(NAV, limit=functools.partial(limit_scale, limits=half, geometry=geometry,
                                            max_wheel_speed_rad_s=16.0))
    assert core.on_twist('navigation', diagonal, 0.0).scale == pytest.approx(0.5)


def test_the_robots_own_limits_keep_direction():
    """
    motor_params.yaml (0.8 / 0.6 m/s, 2.5 rad/s, 28 rad/s, r 0.04 m, lx + ly 0.215 m).

    (0.8, 0.8, 0): y ratio 0.75, then wheels 1.2 / 0.04 = 30 rad/s: 0.75 * 28 / 30 =
    0.7 -> (0.56, 0.56, 0). A twist within the limits passes unchanged (factor 1).
    """
    core = mux(NAV, limit=ROBOT_LIMIT)
    step = core.on_twist('navigation', (0.8, 0.8, 0.0, 0.0, 0.0, 0.0), 0.0)
    assert step == Step(True, False, 'navigation', True, scale=pytest.approx(0.7))
    assert core.on_twist('navigation', GO, 0.1) == Step(True, False, 'navigation', False)
    out = [0.7 * v for v in (0.8, 0.8, 0.0)]
    assert max(abs(w) for w in inverse_kinematics(ROBOT.geometry, *out)) == pytest.approx(28.0)


def test_an_absurd_twist_is_rejected_not_scaled():
    """
    Beyond 10 x a limit: rejected as a NaN is (source silent, one zero), not run at full speed.

    wz 30 rad/s > 10 x 2.5 rad/s; the text names the axis and the bound.
    """
    core = mux(NAV, limit=ROBOT_LIMIT)
    core.on_twist('navigation', GO, 0.0)
    absurd = (0.0, 0.0, 0.0, 0.0, 0.0, 30.0)
    assert 'angular.z = 30 rad/s is absurd' in core.rejection(absurd)
    assert core.rejection(GO) is None
    assert core.rejection((math.nan,) + GO[1:]) == 'linear.x is nan'
    assert core.on_twist('navigation', absurd, 0.1) == Step(False, True, 'none', True)
    assert core.topic_status('navigation', 0.1) == 'silent'
    assert core.on_twist('navigation', GO, 0.2).forward


# -- after a lock: a new command (issue 31: a stale twist must not resume by itself) -------

def test_the_estop_latch_holds_until_motor_controller_releases_then_a_new_command():
    """
    emergency_stop true, motor_controller latches; false: still locked (by the latch).

    Released (emergency_stop_latched false) while navigation keeps driving: navigation
    is held, its twists are not forwarded, until it sends a zero twist (a new command).
    """
    core = mux(NAV, TELEOP, locks=[E_STOP, LATCH])
    assert core.on_twist('navigation', GO, 0.0).forward
    assert core.on_lock('e_stop', True, 0.1) == Step(False, True, 'locked by e_stop', True)
    core.on_lock('e_stop_latched', True, 0.11)
    assert core.on_lock('e_stop', False, 0.5) == Step(
        False, False, 'locked by e_stop_latched', True)
    for t in (0.6, 0.7, 0.8):
        assert core.on_twist('navigation', GO, t).forward is False
    assert core.topic_status('navigation', 0.8) == 'masked'
    # Cleared: navigation's stale stream stays held however long it goes on.
    assert core.on_lock('e_stop_latched', False, 0.85) == Step(
        False, False, 'held navigation', True)
    for t in (0.9, 1.0, 1.5, 3.0):
        assert core.on_twist('navigation', GO, t) == Step(
            False, False, 'held navigation', False)
    assert core.topic_status('navigation', 3.0) == 'held'
    # A zero twist is a new command: forwarded, and so is everything after it.
    assert core.on_twist('navigation', STOP, 3.1) == Step(True, False, 'navigation', True)
    assert core.on_twist('navigation', GO, 3.2) == Step(True, False, 'navigation', False)


def test_a_held_source_is_rearmed_by_falling_silent_not_by_a_nan():
    """Held teleop: a NaN does not re-arm it; silence for its timeout (0.5 s) does."""
    core = mux(NAV, TELEOP, locks=[E_STOP])
    core.on_twist('teleop', GO, 0.0)
    core.on_lock('e_stop', True, 0.1)
    core.on_twist('teleop', GO, 0.2)
    core.on_lock('e_stop', False, 0.3)
    assert core.on_twist('teleop', (math.nan,) + GO[1:], 0.4).forward is False
    assert core.on_twist('teleop', GO, 0.45) == Step(False, False, 'held teleop', False)
    # Last accepted twist at 0.45: held until 0.95, free after.
    assert core.update(0.95).state == 'held teleop'
    assert core.update(0.96) == Step(False, False, 'none', True)
    assert core.on_twist('teleop', GO, 1.0) == Step(True, False, 'teleop', True)


def test_a_zero_during_the_lock_does_not_rearm_and_new_sources_pass_at_once():
    """A zero while still locked re-arms nothing; a source silent during the lock is new."""
    core = mux(NAV, TELEOP, locks=[E_STOP])
    core.on_twist('navigation', GO, 0.0)
    core.on_lock('e_stop', True, 0.1)
    core.on_twist('navigation', STOP, 0.2)
    core.on_twist('navigation', GO, 0.3)
    assert core.on_lock('e_stop', False, 0.4).state == 'held navigation'
    assert core.on_twist('navigation', GO, 0.45).forward is False
    # Teleop did not drive before: its first twist is a new command.
    assert core.on_twist('teleop', GO, 0.5) == Step(True, False, 'teleop', True)
    assert core.topic_status('navigation', 0.5) == 'held'
    assert core.state_at(0.5) == 'teleop'


def test_a_source_above_the_lock_is_not_held():
    """A lock masks only lower priorities, and holds only those."""
    pause = Entry('pause', 'pause', 0.0, 95)
    core = mux(NAV, TELEOP, locks=[pause])
    core.on_twist('teleop', GO, 0.0)
    core.on_twist('navigation', GO, 0.0)
    core.on_lock('pause', True, 0.1)
    assert core.on_twist('teleop', GO, 0.2).forward
    core.on_lock('pause', False, 0.3)
    assert core.on_twist('teleop', GO, 0.35).forward
    assert core.topic_status('navigation', 0.35) == 'held'
