"""
Who publishes a topic that only certain nodes should publish (pure, no ROS).

An accident detector, not security: the nodes downstream of the command chain
(motor_controller on cmd_vel_safe, velocity_controller on motor_speeds and joint_states,
hardware_interface on motor_efforts) would follow any local process that publishes on
their input, a forgotten ``ros2 topic pub``, a second teleop, a test script, and nothing
would notice. Each of them lists its input's publishers from the ROS graph (rclpy's
``get_publishers_info_by_topic``, on a timer) and gives them to a
:class:`PublisherCheck`, which says when publishers outside the expected node names appear
(stop) and when they are all gone (resume). Whoever names itself like an expected node
passes: keeping other programs out is access control (SROS2), not this check.

Names: an expected name without a leading '/' is relative to the namespace of the node
that checks (as ROS resolves names); '/ns/name' is absolute. Several publishers of one
expected node pass too: a node respawned after a crash is seen beside its old endpoint
until DDS declares that one dead. An endpoint whose node rmw does not know (yet) has
placeholder names (:data:`UNKNOWN_NODE_NAME`): that is normal for a moment during
discovery, so it counts only when it is still there at the next check (a DDS program
that is no ROS node publishing on the topic).
"""

import re
from typing import Iterable, List, Mapping, Optional, Sequence, Tuple

#: rmw's node name and namespace of an endpoint whose node it has not discovered.
UNKNOWN_NODE_NAME = '_NODE_NAME_UNKNOWN_'
UNKNOWN_NAMESPACE = '_NODE_NAMESPACE_UNKNOWN_'
#: How an endpoint of no known node is named in messages.
UNKNOWN_LABEL = '(an endpoint of no known ROS node)'

_NAME = re.compile(r'^/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*$')


#: Steady seconds after a new publisher of a watched input matched at which the node's
#: publisher check runs (then again at its period).
MATCH_RECHECK_DELAYS_S = (0.1, 0.3)
#: After those, while a publisher of a watched input has no node name yet: a look every
#: MATCH_UNNAMED_PERIOD_S up to MATCH_UNNAMED_LIMIT_S after the match (steady seconds).
MATCH_UNNAMED_PERIOD_S = 0.2
MATCH_UNNAMED_LIMIT_S = 10.0
#: The steady timer of those looks (s): every delay above is a multiple of it.
MATCH_TIMER_PERIOD_S = 0.1


def match_look_due(since_s: float, looks_done: int, unnamed: bool) -> bool:
    """
    Tell whether a look is due since_s steady seconds after a match (the schedule).

    looks_done: the looks made since the match; unnamed: a watched input has a publisher
    whose node name has not reached the graph yet. The looks: at each of
    MATCH_RECHECK_DELAYS_S, then, while unnamed, every MATCH_UNNAMED_PERIOD_S up to
    MATCH_UNNAMED_LIMIT_S.
    """
    eps = 1e-6
    fixed = len(MATCH_RECHECK_DELAYS_S)
    if looks_done < fixed:
        return since_s + eps >= MATCH_RECHECK_DELAYS_S[looks_done]
    next_s = MATCH_RECHECK_DELAYS_S[-1] + (looks_done - fixed + 1) * MATCH_UNNAMED_PERIOD_S
    return unnamed and since_s + eps >= min(next_s, MATCH_UNNAMED_LIMIT_S)


def match_watch_over(since_s: float, looks_done: int, unnamed: bool) -> bool:
    """Tell whether the looks after a match are over (the same arguments)."""
    return looks_done >= len(MATCH_RECHECK_DELAYS_S) and (
        not unnamed or since_s + 1e-6 >= MATCH_UNNAMED_LIMIT_S)


def parse_expected_publishers(parameter: str, value) -> Tuple[str, ...]:
    """
    Return the node names of a parameter: '' (or nothing) = no check.

    value is a string of names separated by commas or spaces ('zone_guard, teleop') or a
    list of names. Raises ValueError naming the parameter for anything else.
    """
    if value is None:
        return ()
    if isinstance(value, str):
        items = [item for item in re.split(r'[\s,]+', value) if item]
    elif isinstance(value, (list, tuple)):
        items = list(value)
    else:
        raise ValueError(f'parameter {parameter} must be node names (a string such as '
                         f"'zone_guard, teleop' or a list), got {value!r}")
    for item in items:
        if not isinstance(item, str) or not _NAME.match(item):
            raise ValueError(
                f'parameter {parameter}: {item!r} is not a node name (letters, digits and '
                "'_', not starting with a digit; '/namespace/name' for another namespace)")
    return tuple(items)


def qualified_name(name: str, namespace: str = '/') -> str:
    """Return the fully qualified name of a node name relative to namespace."""
    if name.startswith('/'):
        return name
    return namespace.rstrip('/') + '/' + name


def _is_unknown(node_name: str, node_namespace: str) -> bool:
    return node_name == UNKNOWN_NODE_NAME or node_namespace == UNKNOWN_NAMESPACE


def unexpected_publishers(expected: Iterable[str], publishers: Iterable[Tuple[str, str]],
                          namespace: str = '/') -> List[str]:
    """
    Return the publishers (node name, node namespace) that are not expected, sorted.

    Each is named once, fully qualified; endpoints of no known node as UNKNOWN_LABEL.
    """
    allowed = {qualified_name(name, namespace) for name in expected}
    found = set()
    for node_name, node_namespace in publishers:
        if _is_unknown(node_name, node_namespace):
            found.add(UNKNOWN_LABEL)
            continue
        name = qualified_name(node_name, node_namespace or '/')
        if name not in allowed:
            found.add(name)
    return sorted(found)


class PublisherCheck:
    """
    The publishers of one topic, checked again and again against the expected nodes.

    update() takes the topic's publishers now and returns 'stop' when the set of
    unexpected ones appears or changes (log it, stop the robot), 'resume' when they have
    been gone for resume_after updates in a row, None otherwise. consequence and
    resumption say what the node does then, for the messages. With no expected names the
    check is off (enabled False).
    """

    def __init__(self, topic: str, expected: Sequence[str], namespace: str = '/',
                 consequence: str = 'stopping', resumption: str = 'resuming',
                 resume_after: int = 1):
        """Check topic (fully qualified) against expected node names."""
        if resume_after < 1:
            raise ValueError(f'resume_after must be >= 1, got {resume_after}')
        self.topic = topic
        self.expected = tuple(qualified_name(name, namespace) for name in expected)
        self.namespace = namespace
        self.consequence = consequence
        self.resumption = resumption
        self.resume_after = resume_after
        self.intruders: Tuple[str, ...] = ()
        self.departed: Tuple[str, ...] = ()
        self._unknown_before = False
        self._clean_updates = 0
        #: The last update saw an endpoint of no known node (its name may be on its way).
        self.unknown_seen = False

    @property
    def enabled(self) -> bool:
        """Tell whether there is anything to check (expected names given)."""
        return bool(self.expected)

    @property
    def stopped(self) -> bool:
        """Tell whether unexpected publishers are there (the robot must not move)."""
        return bool(self.intruders)

    def update(self, publishers: Iterable, may_resume: bool = True) -> Optional[str]:
        """
        Take the topic's publishers now; return 'stop', 'resume' or None (no change).

        publishers: (node name, node namespace) pairs, or objects with node_name and
        node_namespace (rclpy's TopicEndpointInfo). may_resume False: an extra look
        between the periodic ones (a new publisher matched), which stops for a named
        stranger but neither resumes, nor counts toward resume_after, nor judges an
        endpoint of no known node.
        """
        if not self.enabled:
            return None
        publishers = [(p.node_name, p.node_namespace) if hasattr(p, 'node_name') else p
                      for p in publishers]
        found = unexpected_publishers(self.expected, publishers, self.namespace)
        self.unknown_seen = UNKNOWN_LABEL in found
        if not may_resume:
            # An extra look: a named stranger stops at once; an endpoint of no known node
            # is left to the periodic looks (its name may be on its way: under load it
            # takes longer than these looks are apart, and a false stop is an ERROR).
            found = [name for name in found if name != UNKNOWN_LABEL]
            if not found:
                return None
        else:
            if self.unknown_seen and not self._unknown_before:
                found.remove(UNKNOWN_LABEL)   # perhaps discovery in progress: look again
            self._unknown_before = self.unknown_seen
        found = tuple(found)
        self._clean_updates = 0 if found else self._clean_updates + 1
        if found == self.intruders or (not found and self._clean_updates < self.resume_after):
            return None
        previous, self.intruders = self.intruders, found
        self.departed = tuple(name for name in previous if name not in found)
        return 'stop' if found else 'resume'

    @property
    def level(self) -> str:
        """Return 'error' while unexpected publishers are there, else 'ok'."""
        return 'error' if self.stopped else 'ok'

    @property
    def message(self) -> str:
        """Describe the state now, for the log and /diagnostics."""
        expected = ', '.join(self.expected)
        if self.stopped:
            return (f'{self.topic} has unexpected publisher(s): {", ".join(self.intruders)} '
                    f'(expected only {expected}); {self.consequence} until they are gone')
        return f'{self.topic}: publishers as expected ({expected})'

    @property
    def gone_message(self) -> str:
        """Say that the publishers that were unexpected have gone (after 'resume')."""
        return (f'{self.topic}: unexpected publisher(s) {", ".join(self.departed)} gone; '
                f'{self.resumption}')

    @property
    def values(self) -> List[Tuple[str, str]]:
        """Return key-value pairs for /diagnostics."""
        return [('topic', self.topic), ('expected_publishers', ', '.join(self.expected)),
                ('unexpected_publishers', ', '.join(self.intruders))]


def other_check_holds(status_name: str, values: Mapping[str, str], topic: str,
                      own_name: str) -> Optional[bool]:
    """
    Read another node's publisher check of topic from its /diagnostics status.

    True: that node sees unexpected publishers of topic, so it holds its output at zero
    (hardware_interface on motor_efforts: the board); False: it sees none; None: the
    status is not such a check (or is own_name's own). status_name is
    ``'mecanum_control: NODE publishers of TOPIC'``, values its key-value pairs.
    """
    suffix = f' publishers of {topic}'
    if not status_name.endswith(suffix) or status_name.endswith(f' {own_name}{suffix}'):
        return None
    return bool(values.get('unexpected_publishers', '').strip())
