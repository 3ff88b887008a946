"""
Which topics of a bag ``ros2 bag play`` plays (pure, no rclpy): rosbag2's allow_topic.

Names are absolute topic names; a service is selected by its service event topic
(``/add_two_ints/_service_event``). Patterns are Python regular expressions that must
match the whole name (rosbag2 uses std::regex_match). Rules, in order: an excluded topic
(``--exclude-topics``) or service (``--exclude-services``) or a name matching
``--exclude-regex`` is not played; else, when ``--topics``/``--services`` or ``--regex``
is given, a name is played if listed or matching the regex; else every topic is played.
``--clock`` also leaves the bag's /clock out (the player publishes its own).
"""

from dataclasses import dataclass, field
import re
from typing import List, Optional, Pattern

from ros2bag_mcap.info import is_service_event_topic


def compile_regex(option: str, pattern: str) -> Optional[Pattern]:
    """Compile an option's regular expression ('' = none); ValueError naming the option."""
    if not pattern:
        return None
    try:
        return re.compile(pattern)
    except re.error as error:
        raise ValueError(f'{option}: not a valid regular expression ({error}): '
                         f'{pattern!r}') from None


@dataclass
class TopicFilter:
    """What the play options select: lists of absolute names and the two patterns."""

    topics: List[str] = field(default_factory=list)
    services: List[str] = field(default_factory=list)  # service event topic names
    regex: str = ''
    exclude_regex: str = ''
    exclude_topics: List[str] = field(default_factory=list)
    exclude_services: List[str] = field(default_factory=list)

    def __post_init__(self):
        """Compile the patterns (ValueError for a bad one)."""
        self._regex = compile_regex('--regex', self.regex)
        self._exclude = compile_regex('--exclude-regex', self.exclude_regex)

    def allows(self, name: str, type_name: str) -> bool:
        """Tell whether a topic of this type is played."""
        service = is_service_event_topic(name, type_name)
        if name in (self.exclude_services if service else self.exclude_topics):
            return False
        if self._exclude is not None and self._exclude.fullmatch(name):
            return False
        listed = self.services if service else self.topics
        if listed or self._regex is not None:
            if name in listed:
                return True
            return self._regex is not None and self._regex.fullmatch(name) is not None
        return True
