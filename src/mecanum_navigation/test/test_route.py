"""Routes (NavigateThroughPoses, FollowWaypoints sequencing), cases worked out by hand."""

from mecanum_navigation.navigator.route import NONE, Route
import pytest

STUCK = 9104


def test_poses_in_order_then_done():
    route = Route(3)
    assert (route.index, route.poses_remaining) == (0, 2)
    assert route.leg_ended(NONE) == 1
    assert route.poses_remaining == 1
    assert route.leg_ended(NONE) == 2
    assert route.leg_ended(NONE) is None
    assert route.done and route.error_code == NONE and route.missed == []


def test_first_failure_ends_the_route_with_its_code():
    route = Route(3)
    route.leg_ended(NONE)
    assert route.leg_ended(STUCK, 'stuck') is None
    assert route.done and (route.error_code, route.error_msg) == (STUCK, 'stuck')
    assert route.missed == [(1, STUCK, 'stuck')]
    with pytest.raises(RuntimeError):
        route.leg_ended(NONE)


def test_waypoints_go_on_after_a_miss_when_told_to():
    route = Route(3, stop_on_failure=False)
    assert route.leg_ended(STUCK, 'stuck') == 1
    assert route.leg_ended(NONE) == 2
    assert route.leg_ended(STUCK, 'again') is None
    assert route.done and route.error_code == NONE
    assert route.missed == [(0, STUCK, 'stuck'), (2, STUCK, 'again')]


def test_start_index_and_loops():
    # Start at waypoint 1 of 3, one extra loop: 1, 2, then 0, 1, 2.
    route = Route(3, start_index=1, loops=1)
    visited = [route.index]
    while (index := route.leg_ended(NONE)) is not None:
        visited.append(index)
    assert visited == [1, 2, 0, 1, 2]


def test_abort_keeps_the_first_end():
    route = Route(2)
    route.abort(9105, 'cancelled')
    route.abort(9106, 'preempted')
    assert route.done and route.error_code == 9105


@pytest.mark.parametrize('kwargs', [{'count': 0}, {'count': 2, 'start_index': 2},
                                    {'count': 2, 'start_index': -1},
                                    {'count': 2, 'loops': -1}])
def test_bad_routes_are_refused(kwargs):
    with pytest.raises(ValueError):
        Route(**kwargs)
