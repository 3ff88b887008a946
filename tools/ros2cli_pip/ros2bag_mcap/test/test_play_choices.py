"""Play's choices without ROS: the QoS offered per topic, and which topics play."""

import pytest
from ros2bag_mcap.offer import (DEFAULT_OFFER, duration_ns, Offer, parse_overrides,
                                parse_profile, playback_offer)
from ros2bag_mcap.selection import TopicFilter

INFINITE = {'sec': 9223372036, 'nsec': 854775807}


def recorded(durability='volatile', reliability='reliable', lifespan=INFINITE, depth=0):
    """Return a profile as rosbag2 (metadata version 9) records a publisher's offer."""
    return {'history': 'unknown', 'depth': depth, 'reliability': reliability,
            'durability': durability, 'deadline': INFINITE, 'lifespan': lifespan,
            'liveliness': 'automatic', 'liveliness_lease_duration': INFINITE,
            'avoid_ros_namespace_conventions': False}


def test_no_recorded_profile_plays_reliable_volatile_keep_last_10():
    assert playback_offer([]) == (Offer('keep_last', 10, 'reliable', 'volatile'), '')


def test_latched_topics_play_transient_local_with_history_keep_last_10():
    offer, warning = playback_offer([recorded('transient_local'), recorded('transient_local')])
    assert warning == ''
    assert (offer.history, offer.depth, offer.reliability, offer.durability) == (
        'keep_last', 10, 'reliable', 'transient_local')
    # rmw's infinite durations are "unspecified" (0); liveliness as recorded.
    assert (offer.deadline_ns, offer.lifespan_ns, offer.liveliness_lease_duration_ns) == (
        0, 0, 0)
    assert offer.liveliness == 'automatic'


def test_a_finite_lifespan_is_kept_and_does_not_decide_matching():
    offer, warning = playback_offer([recorded(lifespan={'sec': 10, 'nsec': 0}),
                                     recorded(lifespan={'sec': 2, 'nsec': 5})])
    assert warning == '' and offer.lifespan_ns == 10 * 10 ** 9


def test_publishers_that_differ_get_the_default_and_a_warning():
    offer, warning = playback_offer([recorded('transient_local'), recorded('volatile')])
    assert offer == DEFAULT_OFFER and 'not all recorded publishers' in warning
    offer, warning = playback_offer([recorded(reliability='best_effort'), recorded()])
    assert offer == DEFAULT_OFFER and warning


def test_version_8_numbers_and_project_profiles():
    # Version 8: history 1 keep_last, reliability 2 best_effort, durability 1 transient_local.
    offer = parse_profile({'history': 1, 'depth': 5, 'reliability': 2, 'durability': 1,
                           'deadline': {'sec': 0, 'nsec': 0},
                           'lifespan': {'sec': 0, 'nsec': 0}, 'liveliness': 1,
                           'liveliness_lease_duration': {'sec': 0, 'nsec': 0},
                           'avoid_ros_namespace_conventions': False})
    assert (offer.history, offer.depth, offer.reliability, offer.durability,
            offer.liveliness) == ('keep_last', 5, 'best_effort', 'transient_local',
                                  'automatic')
    # 'unknown' (what rmw reports for a remote publisher's history) is the system default.
    assert parse_profile({'history': 'unknown', 'liveliness': 'unknown'}).history == \
        'system_default'


def test_durations():
    assert duration_ns({'sec': 1, 'nsec': 5}) == 1_000_000_005
    assert duration_ns(INFINITE) == 0
    assert duration_ns({'sec': 0x7FFFFFFF, 'nsec': 0xFFFFFFFF}) == 0  # Foxy's Fast DDS
    for bad in ({'sec': 1}, {'sec': -2, 'nsec': 0}, {'sec': 'a', 'nsec': 0}, 5):
        with pytest.raises(ValueError):
            duration_ns(bad)


def test_bad_recorded_profiles_are_errors():
    for bad in ({'reliability': 'sometimes'}, {'durability': 9}, {'depth': -1}, 'reliable'):
        with pytest.raises(ValueError):
            parse_profile(bad)


def test_overrides_file():
    overrides = parse_overrides({'/map': {'durability': 'transient_local', 'depth': 1},
                                 '/scan': {'reliability': 'best_effort',
                                           'history': 'keep_all'}})
    assert overrides['/map'] == Offer(depth=1, durability='transient_local')
    assert (overrides['/scan'].reliability, overrides['/scan'].history) == (
        'best_effort', 'keep_all')
    assert parse_overrides(None) == {}
    with pytest.raises(ValueError, match="/map.*unexpected key 'durabilty'"):
        parse_overrides({'/map': {'durabilty': 'transient_local'}})
    with pytest.raises(ValueError, match='must map topic names'):
        parse_overrides(['/map'])


STRING = 'std_msgs/msg/String'
EVENT = 'example_interfaces/srv/AddTwoInts_Event'


def played(topic_filter, names=('/a', '/b', '/c/d')):
    """Return the topics (std_msgs/String) and service events a filter lets play."""
    topics = [n for n in names if topic_filter.allows(n, STRING)]
    if topic_filter.allows('/add/_service_event', EVENT):
        topics.append('/add')
    return topics


def test_every_topic_plays_by_default():
    assert played(TopicFilter()) == ['/a', '/b', '/c/d', '/add']


def test_topics_list_and_regex_select_per_kind_as_rosbag2():
    # --topics limits topics; service events are still played (their list is empty).
    assert played(TopicFilter(topics=['/b'])) == ['/b', '/add']
    assert played(TopicFilter(services=['/add/_service_event'])) == ['/a', '/b', '/c/d', '/add']
    assert played(TopicFilter(topics=['/b'], services=['/x/_service_event'])) == ['/b']
    # A regex must match the whole name; listed names play whatever the regex says.
    assert played(TopicFilter(regex='/c')) == []
    assert played(TopicFilter(regex='/c.*')) == ['/c/d']
    assert played(TopicFilter(topics=['/a'], regex='/c.*')) == ['/a', '/c/d']


def test_exclusions_win():
    assert played(TopicFilter(exclude_topics=['/a'])) == ['/b', '/c/d', '/add']
    assert played(TopicFilter(topics=['/a', '/b'], exclude_topics=['/a'])) == ['/b', '/add']
    assert played(TopicFilter(exclude_regex='/(a|add.*)')) == ['/b', '/c/d']
    assert played(TopicFilter(exclude_services=['/add/_service_event'])) == ['/a', '/b', '/c/d']


def test_bad_regex_names_the_option():
    with pytest.raises(ValueError, match='--exclude-regex'):
        TopicFilter(exclude_regex='(')
