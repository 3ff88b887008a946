"""
Twist multiplexer (pure core, no ROS): twist_mux's rules, plus a stop when no source is left.

The rules are those of ros-teleop/twist_mux (ROS 2, ``twist_mux.cpp`` and
``topic_handle.hpp``), with its parameter layout, so a twist_mux YAML file works unchanged:

- ``topics.NAME.topic`` / ``.timeout`` (s) / ``.priority`` (0-255): the velocity inputs.
  A topic is live when its last twist is at most ``timeout`` s old on the node's clock
  (``timeout`` 0: it never expires once it has spoken).
- ``locks.NAME.topic`` (std_msgs/Bool) / ``.timeout`` / ``.priority``: a lock is engaged
  while its last value is true, or, with ``timeout`` > 0, when it has sent nothing for
  ``timeout`` s (or never: its publisher must prove it is alive). ``timeout`` 0: only the
  value counts (nothing received: free).
- The lock priority is the highest priority of the engaged locks (0 when none is). A
  topic is masked when it is not live or its priority is *below* the lock priority
  (strictly, as twist_mux: a lock does not mask a topic of its own priority).
- The selected topic is the unmasked one with the highest priority; on a tie the first
  in twist_mux's order wins (the entries sorted by parameter name, i.e. by NAME), and, as
  in twist_mux, a priority-0 topic is never selected. A twist is forwarded when its own
  topic is the selected one at the moment it arrives; nothing else is published.

Entries are read in twist_mux's order: its ``list_parameters`` walks rclcpp's parameter
map, which is sorted by name, and keeps each prefix at its first appearance.

Deliberate differences from twist_mux (safety):

- When the selection goes from a source to no source at all (the selected topic timed
  out or sent a non-finite twist, or a lock engaged and masks it) the mux sends ONE zero
  twist at once (``Step.stop``), so the robot stops without waiting for the motor
  controller's watchdog. twist_mux then simply falls silent. While no source is
  selected nothing else is published. A selection that moves to another live source
  sends no zero: that source's next twist follows.
- A twist with a NaN or infinite component is not forwarded and counts as its source
  falling silent (twist_mux forwards it).
- A topic that has never sent anything is silent. twist_mux compares with a stamp 0,
  so on simulated time every topic looks live during its first ``timeout`` s.
- A stamp in the future (the clock jumped back, e.g. a restarted simulation) counts as
  expired; twist_mux would keep such an input live until the clock catches up.
- Bad parameters raise ValueError naming the parameter (twist_mux clamps priorities to
  0-255 and accepts negative or non-finite timeouts); two entries on one topic and a
  configuration without topics are refused.
- The robot's limits (``limit``: mecanum_control.command_limits.limit_scale with
  motor_params.yaml) apply to every forwarded twist: one over the limits is scaled down
  as a whole (``Step.scale``, direction kept), the way motor_controller limits it, so
  that the later stages (collision_monitor, zone_guard) judge the twist the wheels will
  run. A twist beyond ``absurd_factor`` times a limit is garbage: rejected as a
  non-finite one (not forwarded, its source counts as silent), not scaled to full speed.
- A lock stops the sources it masks until each sends a NEW command: a topic that was
  live while masked by an engaged lock is *held* after the lock releases, and stays
  held (not selectable) until it sends a zero twist or falls silent for its timeout
  (an accepted twist's age; a NaN does not count). A source that did not speak under
  the lock is new and passes at once. twist_mux resumes the masked sources at once, so
  a stale stream (e.g. navigation still publishing its last command) would drive the
  robot again by itself after an emergency stop.
"""

from dataclasses import dataclass
import math
from typing import Callable, Dict, List, Mapping, Optional, Sequence, Tuple

#: limit((vx, vy, wz)) -> the factor in (0, 1] bringing a twist within the robot's
#: limits; raises ValueError for a twist to reject (command_limits.limit_scale).
Limit = Callable[[Tuple[float, float, float]], float]

#: twist_mux's priority range.
PRIORITY_MIN, PRIORITY_MAX = 0, 255
#: The keys of one entry (every one required, as twist_mux's fetch_param).
ENTRY_KEYS = ('topic', 'timeout', 'priority')
#: The state when no source is selected and no lock is engaged.
NONE = 'none'
#: The state when no source is selected and a lock is engaged: 'locked by NAME'.
LOCKED_BY = 'locked by '
#: The state when no source is selected, no lock engaged, and a source waits for a new
#: command after a lock: 'held NAME' (the highest-priority one).
HELD = 'held '
#: The components of a twist as the node passes them (linear x y z, angular x y z).
COMPONENTS = ('linear.x', 'linear.y', 'linear.z', 'angular.x', 'angular.y', 'angular.z')


@dataclass(frozen=True)
class Entry:
    """One input of the mux: a velocity topic or a lock (twist_mux's TopicHandle)."""

    name: str
    topic: str
    timeout_s: float
    priority: int


@dataclass(frozen=True)
class Step:
    """
    What to publish after an event.

    forward: publish the twist that just arrived, times scale (1: unchanged; below 1:
    it was over the robot's limits). stop: publish one zero twist (the selection has
    just become no source). state: the selected source's name, 'locked by LOCK',
    'held TOPIC' or 'none'; changed: state differs from the last step's.
    """

    forward: bool
    stop: bool
    state: str
    changed: bool
    scale: float = 1.0


def _group_error(group: str, text: str) -> ValueError:
    return ValueError(f'parameter {group}{text}')


def _check_topic(name: str, value) -> str:
    if not isinstance(value, str) or not value:
        raise ValueError(f'parameter {name} must be a non-empty topic name, got {value!r}')
    return value


def _check_timeout(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f'parameter {name} must be a number of seconds, got {value!r}')
    value = float(value)
    if not (math.isfinite(value) and value >= 0.0):
        raise ValueError(f'parameter {name} must be finite and >= 0 (s; 0 = never times '
                         f'out), got {value!r}')
    return value


def _check_priority(name: str, value) -> int:
    if isinstance(value, float) and math.isfinite(value) and value.is_integer():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f'parameter {name} must be an integer {PRIORITY_MIN}-{PRIORITY_MAX}, '
                         f'got {value!r}')
    if not PRIORITY_MIN <= value <= PRIORITY_MAX:
        raise ValueError(f'parameter {name} must be within {PRIORITY_MIN}-{PRIORITY_MAX}, '
                         f'got {value}')
    return value


def parse_entries(group: str, parameters: Mapping[str, object]) -> Tuple[List[Entry], List[str]]:
    """
    Return the entries of group ('topics' or 'locks') in twist_mux's order, and warnings.

    parameters: the node's parameters {full name: value}, e.g.
    {'topics.navigation.topic': 'cmd_vel_smoothed', 'topics.navigation.timeout': 0.5, ...};
    those outside ``group.`` are ignored. An entry is every name up to the last '.' (its
    NAME is that without ``group.``); it needs topic, timeout and priority. Unknown keys
    of an entry give a warning (twist_mux ignores them). Raises ValueError naming the
    parameter for a missing or bad value.
    """
    if group in parameters:
        raise _group_error(group, f' must be a map of entries (NAME: {{topic: ..., timeout: '
                                  f'..., priority: ...}}), got {parameters[group]!r}')
    prefix = group + '.'
    prefixes: List[str] = []
    for full_name in sorted(name for name in parameters if name.startswith(prefix)):
        entry_prefix = full_name.rsplit('.', 1)[0]
        if entry_prefix == group:
            raise ValueError(f'parameter {full_name} must be a map with '
                             f'{", ".join(ENTRY_KEYS)}, got {parameters[full_name]!r}')
        if entry_prefix not in prefixes:
            prefixes.append(entry_prefix)
    entries, warnings = [], []
    for entry_prefix in prefixes:
        name = entry_prefix[len(prefix):]
        for key in ENTRY_KEYS:
            if f'{entry_prefix}.{key}' not in parameters:
                raise ValueError(f'parameter {entry_prefix}.{key} is missing (each entry of '
                                 f'{group} needs {", ".join(ENTRY_KEYS)})')
        entry = Entry(
            name,
            _check_topic(f'{entry_prefix}.topic', parameters[f'{entry_prefix}.topic']),
            _check_timeout(f'{entry_prefix}.timeout', parameters[f'{entry_prefix}.timeout']),
            _check_priority(f'{entry_prefix}.priority',
                            parameters[f'{entry_prefix}.priority']))
        entries.append(entry)
        unknown = sorted(full_name for full_name in parameters
                         if full_name.startswith(entry_prefix + '.')
                         and full_name.rsplit('.', 1)[0] == entry_prefix
                         and full_name.rsplit('.', 1)[1] not in ENTRY_KEYS)
        if unknown:
            warnings.append(f'parameter {", ".join(unknown)} ignored (an entry has only '
                            f'{", ".join(ENTRY_KEYS)})')
        if group == 'topics' and entry.priority == 0:
            warnings.append(f'parameter {entry_prefix}.priority is 0: as in twist_mux, a '
                            'priority-0 topic is never selected')
        if group == 'locks' and entry.priority == 0:
            warnings.append(f'parameter {entry_prefix}.priority is 0: the lock masks nothing')
    return entries, warnings


def non_finite_component(twist: Sequence[float]) -> Optional[str]:
    """Return 'linear.x is nan' for the first non-finite component of twist, else None."""
    for label, value in zip(COMPONENTS, twist):
        if not math.isfinite(value):
            return f'{label} is {value}'
    return None


def _planar(twist: Sequence[float]) -> Tuple[float, float, float]:
    """Return (linear.x, linear.y, angular.z) of a 6-component twist."""
    return float(twist[0]), float(twist[1]), float(twist[5])


class TwistMux:
    """
    The mux's state: when each input last spoke, the lock values, the selection.

    Times are seconds on the node's clock (simulated time works). Events: on_twist,
    on_lock; update (a timer, e.g. 20 Hz) notices timeouts, since a silent source
    causes no event. Each returns the Step to publish.
    """

    def __init__(self, topics: Sequence[Entry], locks: Sequence[Entry] = (),
                 resolve: Callable[[str], str] = str, limit: Optional[Limit] = None):
        """
        Check the configuration (ValueError naming the parameters) and start silent.

        resolve: topic name -> the name it means (the node's resolver, so that
        'cmd_vel' and '/cmd_vel' count as the same topic). limit: the robot's limits
        (see Limit; None: twists are forwarded unscaled, as by twist_mux).
        """
        if not topics:
            raise ValueError('parameter topics is empty: no command sources (topics.NAME.'
                             'topic, .timeout, .priority; see config/twist_mux.yaml)')
        seen: Dict[str, str] = {}
        for group, entries in (('topics', topics), ('locks', locks)):
            names = [entry.name for entry in entries]
            if len(set(names)) != len(names):
                raise ValueError(f'parameter {group} has a name twice: {names}')
            for entry in entries:
                key = f'{group}.{entry.name}.topic'
                try:
                    resolved = resolve(entry.topic)
                except Exception as error:  # the resolver's own exception types
                    raise ValueError(f'parameter {key} is not a valid topic name: '
                                     f'{error}') from None
                if resolved in seen:
                    raise ValueError(f'parameters {seen[resolved]} and {key} name the same '
                                     f'topic {resolved}: one entry per topic')
                seen[resolved] = key
        self.topics = list(topics)
        self.locks = list(locks)
        self._topic_stamp: Dict[str, Optional[float]] = {e.name: None for e in self.topics}
        self._lock_stamp: Dict[str, Optional[float]] = {e.name: None for e in self.locks}
        self._lock_value: Dict[str, bool] = {e.name: False for e in self.locks}
        # The last accepted twist of each topic (a NaN does not reset it), and whether
        # the topic is held after a lock (see the module docstring).
        self._accepted_stamp: Dict[str, Optional[float]] = {e.name: None for e in self.topics}
        self._held: Dict[str, bool] = {e.name: False for e in self.topics}
        self._limit = limit
        self._topics = {entry.name: entry for entry in self.topics}
        self._locks = {entry.name: entry for entry in self.locks}
        self.source: Optional[str] = None
        self.state = ''   # not reported yet: the first step says changed

    # -- inputs -------------------------------------------------------------------------

    @staticmethod
    def _expired(entry: Entry, stamp: Optional[float], now_s: float) -> bool:
        """twist_mux's hasExpired; also never received, or stamped in the future."""
        if entry.timeout_s <= 0.0:
            return False
        return stamp is None or now_s < stamp or now_s - stamp > entry.timeout_s

    def topic_live(self, name: str, now_s: float) -> bool:
        """Return whether topic NAME has spoken within its timeout (and never NaN since)."""
        stamp = self._topic_stamp[name]
        return stamp is not None and not self._expired(self._topics[name], stamp, now_s)

    def lock_engaged(self, name: str, now_s: float) -> bool:
        """Return whether lock NAME is true, or (timeout > 0) has timed out."""
        entry = self._locks[name]
        return self._lock_value[name] or self._expired(entry, self._lock_stamp[name], now_s)

    def lock_priority(self, now_s: float) -> int:
        """Return the highest priority of the engaged locks, 0 if none (twist_mux's)."""
        return max([e.priority for e in self.locks if self.lock_engaged(e.name, now_s)],
                   default=0)

    def masked(self, name: str, now_s: float) -> bool:
        """twist_mux's isMasked: not live, or priority below the lock priority."""
        return (not self.topic_live(name, now_s)
                or self._topics[name].priority < self.lock_priority(now_s))

    def held(self, name: str, now_s: float) -> bool:
        """Return whether topic NAME waits for a new command after a lock."""
        entry, stamp = self._topics[name], self._accepted_stamp[name]
        stopped = stamp is None or (entry.timeout_s > 0.0
                                    and self._expired(entry, stamp, now_s))
        return self._held[name] and not stopped

    def _update_held(self, now_s: float) -> None:
        """Hold every live topic masked by a lock; forget the hold of stopped ones."""
        lock_priority = self.lock_priority(now_s)
        for entry in self.topics:
            if not self.held(entry.name, now_s):
                self._held[entry.name] = False
            if self.topic_live(entry.name, now_s) and entry.priority < lock_priority:
                self._held[entry.name] = True

    def select(self, now_s: float) -> Optional[str]:
        """Return the selected topic's name, or None (twist_mux's hasPriority loop)."""
        best_priority, best = PRIORITY_MIN, None
        for entry in self.topics:
            if (not self.masked(entry.name, now_s) and not self.held(entry.name, now_s)
                    and entry.priority > best_priority):
                best_priority, best = entry.priority, entry.name
        return best

    def state_at(self, now_s: float) -> str:
        """
        Return the state: the selected topic, or why none is selected.

        Else 'locked by LOCK' (the highest engaged lock), else 'held TOPIC' (the
        highest-priority held topic), else 'none'.
        """
        source = self.select(now_s)
        if source is not None:
            return source
        engaged = [e for e in self.locks if self.lock_engaged(e.name, now_s)]
        if engaged:
            return LOCKED_BY + max(engaged, key=lambda e: e.priority).name
        held = [e for e in self.topics if self.held(e.name, now_s)]
        if held:
            return HELD + max(held, key=lambda e: e.priority).name
        return NONE

    # -- events -------------------------------------------------------------------------

    def _step(self, now_s: float, arrived: Optional[str] = None, scale: float = 1.0) -> Step:
        self._update_held(now_s)
        source = self.select(now_s)
        state = self.state_at(now_s)
        forward = arrived is not None and source == arrived
        step = Step(forward=forward, stop=self.source is not None and source is None,
                    state=state, changed=state != self.state,
                    scale=scale if forward else 1.0)
        self.source, self.state = source, state
        return step

    def _check(self, twist: Sequence[float]) -> Tuple[Optional[str], float]:
        """Return (why twist is rejected or None, the factor bringing it within limits)."""
        problem = non_finite_component(twist)
        if problem is not None or self._limit is None:
            return problem, 1.0
        try:
            return None, self._limit(_planar(twist))
        except ValueError as error:
            return str(error), 1.0

    def rejection(self, twist: Sequence[float]) -> Optional[str]:
        """Return why a twist is rejected ('linear.x is nan', '... is absurd ...') or None."""
        return self._check(twist)[0]

    def on_twist(self, name: str, twist: Sequence[float], now_s: float) -> Step:
        """
        Take a twist (linear x y z, angular x y z) from topic NAME at now_s.

        Forwarded when NAME is then the selected topic, times Step.scale; a rejected
        one (non-finite, or absurd for the limits) never is, and makes NAME silent
        until its next accepted twist. A zero twist re-arms a held topic.
        """
        problem, scale = self._check(twist)
        if problem is not None:
            self._topic_stamp[name] = None
            return self._step(now_s)
        self._topic_stamp[name] = self._accepted_stamp[name] = now_s
        if all(value == 0.0 for value in twist):
            self._held[name] = False   # held again by _step if a lock still masks it
        return self._step(now_s, arrived=name, scale=scale)

    def on_lock(self, name: str, value: bool, now_s: float) -> Step:
        """Take lock NAME's value at now_s."""
        self._lock_stamp[name] = now_s
        self._lock_value[name] = bool(value)
        return self._step(now_s)

    def update(self, now_s: float) -> Step:
        """Look at the timeouts at now_s (call it periodically)."""
        return self._step(now_s)

    # -- reporting ----------------------------------------------------------------------

    def topic_status(self, name: str, now_s: float) -> str:
        """
        Return 'selected', 'live', 'masked', 'held' or 'silent'.

        masked: live, below the locks; held: live, waiting for a new command after a
        lock.
        """
        if not self.topic_live(name, now_s):
            return 'silent'
        if self.masked(name, now_s):
            return 'masked'
        if self.held(name, now_s):
            return 'held'
        return 'selected' if self.select(now_s) == name else 'live'

    def lock_status(self, name: str, now_s: float) -> str:
        """Return 'engaged', 'engaged (timed out)' or 'free'."""
        if self._lock_value[name]:
            return 'engaged'
        return 'engaged (timed out)' if self.lock_engaged(name, now_s) else 'free'
