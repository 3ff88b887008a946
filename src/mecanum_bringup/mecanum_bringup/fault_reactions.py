"""
What the robot must do under each fault, and the judging of it (pure, no ROS).

One table, :data:`REACTIONS`, gives each fault kind's expected reaction (for the node
faults, per node); docs/failure_modes.md says the same in words. A scenario with
``criteria: {fault_reactions: true}`` is judged against it for every fault it injected
(:func:`judge_fault_reactions`, one ``fault_reaction`` line in the verdict):

- **stop** (``stop_within_s``): from ``stop_within_s`` after the fault began until it
  ended, the robot is at rest on the ground truth: translation below
  :data:`REST_SPEED_M_S`, and unless turning on the spot is allowed (an unhealthy
  localisation lets the robot turn so that amcl updates) rotation below
  :data:`REST_TURN_RAD_S`. An instant fault is judged until ``stop_until_s`` after it
  (amcl diverged: :data:`AMCL_SPREAD_S`, or until the zone guard states the
  localisation healthy again, if sooner); after a kill, the robot must come to rest
  within the delay at least once (the respawned node may drive it on at once). The
  delays allow for the ramp to rest from the top
  speed (:data:`RAMP_TO_REST_S`) after the stage that notices;
- **says why** (``says``: (node, words) pairs): while the fault acts, a stage of the
  command chain states a stop, lock or hold naming it (its state topic: twist_mux's
  ``cmd_vel_mux_state``, ``collision_monitor_state``, ``zone_guard_state``), unless no
  command source was live then (twist_mux said ``none`` throughout: nothing to stop);
- **travel** (``max_travel_m``): the true robot goes at most that far while the fault
  acts (a stop whose moment depends on how the robot is driven: a stuck encoder is
  noticed only once its wheel has been driven for 0.5 s);
- **mission** (:data:`CONTINUES`): the fault is ridden out or recovered from: every goal
  and waypoints step of the run was reached; (:data:`SAFE`): only the safety invariants
  (no collision, footprint in the zone), which are criteria of their own.

A fault that never acted within the run (its onset after the run's end, a kidnap the
simulator refused, amcl_diverged without amcl) fails the line: the variant tested nothing.
Tracks are (N, 4) arrays t, x, y, yaw (simulated s, m, rad; map frame).
"""

from dataclasses import dataclass
import math
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

#: The robot is at rest below these (ground truth; finite differences at 50 Hz).
REST_SPEED_M_S = 0.02
REST_TURN_RAD_S = 0.05
#: A stage's statement counts from the fault's start to this long after its end (s).
SAYS_GRACE_S = 0.5
#: From a zero command to rest at the top speed: 0.8 m/s at motor_controller's 1.5 m/s^2
#: (motor_params.yaml) is 0.53 s, plus the motors' lag: 0.65 s.
RAMP_TO_REST_S = 0.65
#: A silent chain stage: motor_controller's cmd_timeout_s (0.25 s), then the ramp.
WATCHDOG_STOP_S = 0.25 + RAMP_TO_REST_S

#: amcl_diverged: the robot translates not at all for this long after the spread (s),
#: or until the zone guard finds the localisation healthy again, if that comes sooner.
AMCL_SPREAD_S = 3.0

CONTINUES = 'continues'
SAFE = 'safe'

#: The state of twist_mux when no source is live (mecanum_safety.twist_mux).
MUX_IDLE = 'none'


@dataclass(frozen=True)
class Reaction:
    """The expected reaction to one fault kind (see the module docstring)."""

    does: str
    stop_within_s: Optional[float] = None
    turning_allowed: bool = False
    says: Tuple[Tuple[str, str], ...] = ()
    mission: str = CONTINUES
    #: For instants: at rest until this long after the fault (s; None: until the end,
    #: or until back_node is back).
    stop_until_s: Optional[float] = None
    #: A kill: the robot comes to rest within stop_within_s at least once (the respawned
    #: node may drive it on at once: its return is not seen in the states it publishes).
    momentary: bool = False
    #: The stop may end early once this chain stage states health again (a state with
    #: neither 'STOP' first nor 'unhealthy' in it, after the fault began).
    healthy_again: Optional[str] = None
    #: The true robot travels at most this far (m) while the fault acts (a stop whose
    #: moment depends on how the robot is driven: bounded by the distance instead).
    max_travel_m: Optional[float] = None


_LIDAR = 'collision_monitor'
_CHAIN_NODES = ('twist_mux', 'collision_monitor', 'zone_guard')
_WATCHDOG = "the next stage's command timeout stops the wheels (motor_controller 0.25 s)"

#: kind -> Reaction; node faults: 'kind:node' (a node not listed: 'kind:*').
REACTIONS: Dict[str, Reaction] = {
    'lidar_blinded': Reaction('stops: scan blinded; drives on once beams return', 1.0,
                              says=((_LIDAR, 'scan blinded'),)),
    'lidar_frozen': Reaction('stops after 5 identical scans: scan frozen', 1.5,
                             says=((_LIDAR, 'scan frozen'),)),
    'lidar_silent': Reaction('stops after the 1 s source timeout: scan stale', 2.0,
                             says=((_LIDAR, 'scan stale'), (_LIDAR, 'scan no data'))),
    'scan_stamp_skew': Reaction('stops: scan stamped in the future (or stale)', 1.0,
                                says=((_LIDAR, 'stamped in the future'),
                                      (_LIDAR, 'scan stale'))),
    'imu_silent': Reaction('drives on with wheel odometry (the board reports IMU_FAULT)'),
    'imu_bias': Reaction('drives on; amcl corrects the heading in the map frame'),
    'encoder_stuck': Reaction('every wheel stops once the stuck wheel has been driven '
                              'for 0.5 s (velocity_controller stall check), latched until '
                              '~/clear_wheel_faults', mission=SAFE, max_travel_m=0.6),
    'wheel_slip': Reaction('drives on; amcl corrects the odometry from the scans'),
    'kidnap': Reaction('drives on; amcl relocalises from the scans as the robot moves'),
    'serial_bit_flips': Reaction('drives on: CRC-16 drops the bad frames'),
    'serial_drop_bytes': Reaction('drives on: lost frames dropped, the board holds the '
                                  'last effort up to its 0.15 s command timeout'),
    'serial_latency': Reaction('drives on late; a latency that shakes the wheel speed loop '
                               'can make the localisation unhealthy: then it stops',
                               mission=SAFE),
    'amcl_diverged': Reaction('stops all but turning on the spot: localisation unhealthy '
                              '(or jumped: latched until /initialpose)', 1.5,
                              turning_allowed=True,
                              says=(('zone_guard', 'localisation unhealthy'),),
                              mission=SAFE, stop_until_s=AMCL_SPREAD_S,
                              healthy_again='zone_guard'),
    'estop': Reaction('stops at once (ramped); stays stopped until the operator resets it',
                      RAMP_TO_REST_S + 0.1,
                      says=(('twist_mux', 'e_stop'),), mission=SAFE),
    **{f'node_frozen:{node}': Reaction(f'stops: {_WATCHDOG}; drives on once it resumes',
                                       WATCHDOG_STOP_S + 0.1) for node in _CHAIN_NODES},
    **{f'node_killed:{node}': Reaction(f'stops: {_WATCHDOG}; drives on once respawned',
                                       WATCHDOG_STOP_S + 0.1, momentary=True)
       for node in _CHAIN_NODES},
    'node_frozen:amcl': Reaction('stops: no pose (map -> odom older than 0.5 s); drives on '
                                 'once it resumes', 1.5, says=(('zone_guard', 'no pose'),)),
    'node_killed:amcl': Reaction('the respawned amcl resumes from its saved pose; drives on'),
    'node_frozen:*': Reaction('whatever the node does, the invariants hold', mission=SAFE),
    'node_killed:*': Reaction('whatever the node does, the invariants hold', mission=SAFE),
}


def reaction_for(fault: Mapping[str, Any]) -> Reaction:
    """Return the expected reaction to a fault (a RunRecord.faults entry or FaultSpec dict)."""
    kind = fault['kind']
    if kind in ('node_frozen', 'node_killed'):
        return REACTIONS.get(f'{kind}:{fault.get("node")}', REACTIONS[f'{kind}:*'])
    return REACTIONS[kind]


@dataclass(frozen=True)
class ReactionResult:
    """How one fault's reaction went: passed, and the words for the verdict."""

    passed: bool
    detail: str


def chain_state_at(states: Sequence[Tuple[float, str, str]], node: str,
                   t_s: float) -> Optional[str]:
    """Return node's last state at or before t_s from (t, node, state) changes, or None."""
    current = None
    for time_s, name, text in states:
        if time_s > t_s:
            break
        if name == node:
            current = text
    return current


def judge_reaction(fault: Mapping[str, Any], truth: Any,
                   chain_states: Sequence[Tuple[float, str, str]],
                   goals_reached: Optional[bool]) -> ReactionResult:
    """
    Judge one fault's reaction (see the module docstring).

    fault: a RunRecord.faults entry (kind, began_s, ended_s, node...); truth: (N, 4) t, x,
    y, yaw; chain_states: (t, node, state) at each change of a chain stage's state,
    sorted by t; goals_reached: whether every goal step was reached (None: no goal step).
    """
    reaction = reaction_for(fault)
    name = fault['kind'] + (f' {fault["node"]}' if fault.get('node') else '')
    began, ended = fault.get('began_s'), fault.get('ended_s')
    if began is None:
        return ReactionResult(False, f'{name}: never acted within the run (onset '
                                     f'{fault.get("onset_s", math.nan):.1f} s)')
    if fault.get('applied') is False:
        return ReactionResult(False, f'{name}: not applied: {fault.get("outcome", "")}')
    problems: List[str] = []
    found: List[str] = []
    if reaction.stop_within_s is not None and reaction.momentary:
        _judge_rest_once(reaction, truth, began, problems, found)
    elif reaction.stop_within_s is not None:
        _judge_rest_until(reaction, truth, chain_states, began, ended, problems, found)
    if reaction.max_travel_m is not None:
        end = ended if ended is not None and ended > began else math.inf
        travel = _travel_m(truth, began, end)
        if travel > reaction.max_travel_m:
            problems.append(f'travelled {travel:.2f} m while it acted (at most '
                            f'{reaction.max_travel_m:g} m expected)')
        else:
            found.append(f'travelled {travel:.2f} m while it acted')
    if reaction.says:
        last = (ended if ended is not None and ended > began else
                began + (reaction.stop_until_s or reaction.stop_within_s or 0.0))
        said = _said(chain_states, reaction.says, began, last + SAYS_GRACE_S)
        if said is not None:
            found.append(f'{said[0]} said "{said[1]}"')
        elif _a_source_was_live(chain_states, began, last):
            wanted = ' or '.join(f'{node} "{words}"' for node, words in reaction.says)
            problems.append(f'no stage said why (expected {wanted})')
    if reaction.mission == CONTINUES and goals_reached is False:
        problems.append('a goal was not reached (the robot should drive on or recover)')
    elif reaction.mission == CONTINUES and goals_reached:
        found.append('goals reached')
    if problems:
        return ReactionResult(False, f'{name}: ' + '; '.join(problems))
    return ReactionResult(True, f'{name}: ' + (', '.join(found) or reaction.does))


def _judge_rest_once(reaction: Reaction, truth: Any, began: float, problems: List[str],
                     found: List[str]) -> None:
    """At rest at least once within stop_within_s after began (a kill)."""
    rest = _first_rest_s(truth, began, reaction.turning_allowed)
    if rest is None or rest > began + reaction.stop_within_s:
        when = 'never' if rest is None else f'only {rest - began:.2f} s after'
        problems.append(f'came to rest {when} (within {reaction.stop_within_s:g} s expected)')
    else:
        found.append(f'at rest {rest - began:.2f} s after')


def _judge_rest_until(reaction: Reaction, truth: Any,
                      chain_states: Sequence[Tuple[float, str, str]], began: float,
                      ended: Optional[float], problems: List[str], found: List[str]) -> None:
    """At rest from stop_within_s after began until the fault ended (or as the kind says)."""
    if reaction.stop_until_s is not None:
        end = began + reaction.stop_until_s
    elif ended is not None and ended > began:
        end = ended
    else:
        end = math.inf
    if reaction.healthy_again is not None:
        end = min(end, _healthy_again_s(chain_states, reaction.healthy_again, began))
    moving = _first_motion(truth, began + reaction.stop_within_s, end,
                           reaction.turning_allowed)
    if moving is not None:
        problems.append(f'moving at {moving[1]:.2f} {moving[2]} at t={moving[0]:.2f} s, '
                        f'{moving[0] - began:.2f} s after it began (at rest expected '
                        f'from {reaction.stop_within_s:g} s)')
    else:
        found.append(f'at rest from +{reaction.stop_within_s:g} s'
                     + ('' if math.isinf(end) else f' to +{end - began:.1f} s'))


def _rates(truth: Any) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Return each interval's end t, length dt, speed (m/s) and turn rate (rad/s)."""
    track = np.asarray(truth, dtype=np.float64).reshape(-1, 4)
    if len(track) < 2:
        return (np.zeros(0),) * 4
    dt = np.diff(track[:, 0])
    ok = dt > 1e-6
    dt = dt[ok]
    speed = np.hypot(np.diff(track[:, 1])[ok], np.diff(track[:, 2])[ok]) / dt
    turn = np.abs(np.angle(np.exp(1j * np.diff(track[:, 3])[ok]))) / dt
    return track[1:, 0][ok], dt, speed, turn


def _first_motion(truth: Any, start_s: float, end_s: float,
                  turning_allowed: bool) -> Optional[Tuple[float, float, str]]:
    """Return (t, speed, unit) of the first motion between start_s and end_s, or None."""
    if end_s <= start_s:
        return None
    t, dt, speed, turn = _rates(truth)
    # A sample judges the interval before it: both ends within the window.
    inside = (t - dt >= start_s - 1e-9) & (t <= end_s + 1e-9)
    for index in np.flatnonzero(inside):
        if speed[index] >= REST_SPEED_M_S:
            return float(t[index]), float(speed[index]), 'm/s'
        if not turning_allowed and turn[index] >= REST_TURN_RAD_S:
            return float(t[index]), float(turn[index]), 'rad/s'
    return None


def _healthy_again_s(chain_states: Sequence[Tuple[float, str, str]], node: str,
                     after_s: float) -> float:
    """Return when node first stated health after after_s (inf: never)."""
    for time_s, name, text in chain_states:
        if (time_s > after_s and name == node and not text.startswith('STOP')
                and 'unhealthy' not in text):
            return time_s
    return math.inf


def _first_rest_s(truth: Any, after_s: float, turning_allowed: bool) -> Optional[float]:
    """Return the end time of the first interval at rest after after_s, or None."""
    t, dt, speed, turn = _rates(truth)
    rest = (t - dt >= after_s - 1e-9) & (speed < REST_SPEED_M_S)
    if not turning_allowed:
        rest &= turn < REST_TURN_RAD_S
    index = np.flatnonzero(rest)
    return float(t[index[0]]) if len(index) else None


def _travel_m(truth: Any, start_s: float, end_s: float) -> float:
    """Return the length (m) of the true path between start_s and end_s."""
    track = np.asarray(truth, dtype=np.float64).reshape(-1, 4)
    inside = track[(track[:, 0] >= start_s) & (track[:, 0] <= end_s)]
    if len(inside) < 2:
        return 0.0
    return float(np.sum(np.hypot(np.diff(inside[:, 1]), np.diff(inside[:, 2]))))


def _said(chain_states: Sequence[Tuple[float, str, str]], says: Sequence[Tuple[str, str]],
          start_s: float, end_s: float) -> Optional[Tuple[str, str]]:
    """Return the first (node, state) within [start_s, end_s] that says one of says."""
    for time_s, node, text in chain_states:
        if start_s <= time_s <= end_s and any(
                node == want and words in text for want, words in says):
            return node, text
    return None


def _a_source_was_live(chain_states: Sequence[Tuple[float, str, str]], start_s: float,
                       end_s: float) -> bool:
    """Tell whether twist_mux had a live source at any time in [start_s, end_s]."""
    state = chain_state_at(chain_states, 'twist_mux', start_s)
    if state is not None and state != MUX_IDLE:
        return True
    return any(start_s <= time_s <= end_s and node == 'twist_mux' and text != MUX_IDLE
               for time_s, node, text in chain_states)
