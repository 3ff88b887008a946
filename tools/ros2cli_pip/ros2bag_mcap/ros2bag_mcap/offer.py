"""
The QoS ``ros2 bag play`` offers on a topic, from what the bag recorded (pure, no rclpy).

rosbag2's rule (Jazzy, ``Rosbag2QoS::adapt_offer_to_recorded_offers``): a topic recorded
without ``offered_qos_profiles`` is played reliable, volatile, keep last 10; when every
recorded publisher offered the same policies that matter for matching (reliability,
durability, deadline, liveliness and its lease duration), the player offers that profile
with history keep last 10 (so latched /tf_static and /map are played transient local);
otherwise the default again. A ``--qos-profile-overrides-path`` entry replaces all that.

Profiles are metadata.yaml's: version 9 names policies ('reliable'), versions up to 8
numbers (rmw's enums); durations are ``{sec, nsec}``. rmw's infinite duration (and the
Foxy-era "infinite" values) mean "unspecified" here: 0 ns, which rmw takes as infinite.
A policy recorded as 'unknown' is offered as 'system_default'.
"""

from dataclasses import dataclass, replace
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

from mecanum_bringup.bag_writer import OfferedQos

#: Depth of rosbag2's default history (rmw_qos_profile_default).
DEFAULT_DEPTH = 10
_INFINITE_NS = {2 ** 63 - 1, 0x7FFFFFFF * 10 ** 9 + 0xFFFFFFFF,
                0x7FFFFFFF * 10 ** 9 + 0x7FFFFFFF}
#: rmw's enum values (metadata version <= 8) to names.
_NUMBERED = {
    'history': ('system_default', 'keep_last', 'keep_all', 'unknown'),
    'reliability': ('system_default', 'reliable', 'best_effort', 'unknown', 'best_available'),
    'durability': ('system_default', 'transient_local', 'volatile', 'unknown',
                   'best_available'),
    'liveliness': ('system_default', 'automatic', 'manual_by_node', 'manual_by_topic',
                   'unknown', 'best_available'),
}
_DURATIONS = ('deadline', 'lifespan', 'liveliness_lease_duration')


@dataclass(frozen=True)
class Offer(OfferedQos):
    """
    A publisher QoS: the recorder's OfferedQos (one definition of the fields).

    Policies by rmw name, durations in ns (0 = unspecified = infinite).
    """

    def matching_key(self) -> tuple:
        """Return the policies that decide matching (rosbag2 compares these only)."""
        return (self.reliability, self.durability, self.deadline_ns, self.liveliness,
                self.liveliness_lease_duration_ns)


#: rosbag2's default publisher offer (Rosbag2QoS{}): reliable, volatile, keep last 10.
DEFAULT_OFFER = Offer()


def _policy(kind: str, value) -> str:
    """Return a policy by name from a name or an rmw number; ValueError if neither."""
    names = _NUMBERED[kind]
    if isinstance(value, bool):
        raise ValueError(f'{kind} must be a policy name, got {value!r}')
    if isinstance(value, int):
        if not 0 <= value < len(names):
            raise ValueError(f'{kind} {value} is not an rmw {kind} policy')
        name = names[value]
    elif isinstance(value, str) and value.strip().lower() in names:
        name = value.strip().lower()
    else:
        raise ValueError(f'{kind} must be one of {", ".join(names)}, got {value!r}')
    if name == 'unknown':
        return 'system_default'
    if name == 'manual_by_node':  # deprecated in rmw, accepted by rclpy as by topic
        return 'manual_by_topic'
    return name


def duration_ns(value, name: str = 'duration') -> int:
    """Return a ``{sec, nsec}`` duration in ns; infinite ones as 0 (unspecified)."""
    if not isinstance(value, Mapping) or 'sec' not in value or 'nsec' not in value:
        raise ValueError(f'{name} must be {{sec: S, nsec: N}}, got {value!r}')
    sec, nsec = value['sec'], value['nsec']
    for part in (sec, nsec):
        if isinstance(part, bool) or not isinstance(part, int):
            raise ValueError(f'{name} must hold integers, got {value!r}')
    total = sec * 10 ** 9 + nsec
    if total < 0:
        raise ValueError(f'{name} may not be negative, got {value!r}')
    return 0 if total in _INFINITE_NS or total >= 2 ** 63 - 1 else total


def parse_profile(profile: Mapping, base: Offer = DEFAULT_OFFER,
                  strict: bool = False) -> Offer:
    """
    Return a recorded (or override) QoS profile as an Offer; ValueError if malformed.

    Keys missing from profile keep base's value. strict: an unknown key is an error
    (an overrides file); recorded profiles may carry keys of newer rosbag2 versions.
    """
    if not isinstance(profile, Mapping):
        raise ValueError(f'a QoS profile must be a mapping, got {profile!r}')
    changes: Dict[str, object] = {}
    for key, value in profile.items():
        if key in _NUMBERED:
            changes[key] = _policy(key, value)
        elif key in _DURATIONS:
            changes[key + '_ns'] = duration_ns(value, key)
        elif key == 'depth':
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f'depth must be an integer >= 0, got {value!r}')
            changes['depth'] = value
        elif key == 'avoid_ros_namespace_conventions':
            if not isinstance(value, bool):
                raise ValueError(f'avoid_ros_namespace_conventions must be true or false, '
                                 f'got {value!r}')
            changes[key] = value
        elif strict:
            raise ValueError(f'unexpected key {key!r} for a QoS profile')
    return replace(base, **changes)


def playback_offer(profiles: Sequence[Mapping]) -> Tuple[Offer, str]:
    """
    Return the offer for playing a topic recorded with these publisher profiles, and a warning.

    The warning is '' unless the recorded publishers differ (the default is offered then).
    """
    offers: List[Offer] = [parse_profile(p) for p in profiles]
    if not offers:
        return DEFAULT_OFFER, ''
    if all(o.matching_key() == offers[0].matching_key() for o in offers[1:]):
        return replace(offers[0], history='keep_last', depth=DEFAULT_DEPTH), ''
    return DEFAULT_OFFER, ('not all recorded publishers offered the same QoS; playing with '
                           'the default (reliable, volatile, keep last 10)')


def parse_overrides(document) -> Dict[str, Offer]:
    """
    Return the QoS overrides of a ``--qos-profile-overrides-path`` file, by topic.

    The file maps topic names to profiles (rosbag2's format: policy names, durations as
    {sec, nsec}); missing policies are rosbag2's defaults. ValueError if malformed.
    """
    if document is None:
        return {}
    if not isinstance(document, Mapping):
        raise ValueError('the QoS overrides file must map topic names to QoS profiles')
    overrides = {}
    for topic, profile in document.items():
        try:
            overrides[str(topic)] = parse_profile(profile, strict=True)
        except ValueError as error:
            raise ValueError(f'QoS override of {topic}: {error}') from None
    return overrides


def describe(offer: Optional[Offer]) -> str:
    """Return a short text of an offer, for the log ('reliable, transient_local, depth 10')."""
    if offer is None:
        return 'default'
    history = f'depth {offer.depth}' if offer.history == 'keep_last' else offer.history
    return f'{offer.reliability}, {offer.durability}, {history}'
