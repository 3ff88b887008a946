"""Joint states -> transforms, and the per-joint publishing throttle."""

import math

from mecanum_description.joint_states import joint_state_transforms, PublishThrottle
from mecanum_description.robot_model import parse_urdf
import pytest

H = math.sqrt(0.5)

MODEL = parse_urdf(
    '<robot name="r"><link name="base"/><link name="left"/><link name="right"/>'
    '<link name="lidar"/>'
    '<joint name="lj" type="continuous"><parent link="base"/><child link="left"/>'
    '<origin xyz="0 0.1 0"/><axis xyz="0 1 0"/></joint>'
    '<joint name="rj" type="continuous"><parent link="base"/><child link="right"/>'
    '<origin xyz="0 -0.1 0"/><axis xyz="0 1 0"/><mimic joint="lj" multiplier="2"/></joint>'
    '<joint name="fixed_lidar" type="fixed"><parent link="base"/><child link="lidar"/>'
    '</joint></robot>')


def test_transforms_of_named_joints_and_their_mimics():
    update = joint_state_transforms(MODEL, ['lj'], [math.pi / 2])
    assert update.positions == {'lj': math.pi / 2, 'rj': math.pi}
    left, right = update.transforms
    assert (left.parent, left.child) == ('base', 'left')
    assert left.translation == (0, 0.1, 0)
    assert left.rotation == pytest.approx((0, H, 0, H))
    assert right.child == 'right'
    assert right.rotation == pytest.approx((0, 1, 0, 0))      # half a turn about y
    assert update.unknown == [] and update.not_finite == []


def test_unknown_fixed_and_non_finite_joints_are_left_out():
    update = joint_state_transforms(
        MODEL, ['ghost', 'fixed_lidar', 'lj'], [1.0, 2.0, float('nan')])
    assert update.unknown == ['ghost', 'fixed_lidar']
    assert update.not_finite == ['lj']
    assert update.transforms == [] and update.positions == {}
    update = joint_state_transforms(MODEL, ['rj'], [float('inf')])
    assert update.not_finite == ['rj'] and update.transforms == []


def test_a_joint_given_explicitly_wins_over_its_mimic_rule():
    update = joint_state_transforms(MODEL, ['lj', 'rj'], [1.0, 0.25])
    assert update.positions == {'lj': 1.0, 'rj': 0.25}


def test_names_and_positions_of_different_lengths_are_refused():
    with pytest.raises(ValueError, match='2 names but 1 positions'):
        joint_state_transforms(MODEL, ['lj', 'rj'], [1.0])


def test_throttle_publishes_each_joint_at_most_once_per_interval():
    throttle = PublishThrottle(50)
    assert throttle.ready(['a'], 1000)
    assert not throttle.ready(['a'], 1049)          # 49 ns after: too soon
    assert throttle.ready(['b'], 1049)              # b was never published
    assert throttle.ready(['a'], 1050)              # a full interval after
    # A state with a (last 1050) and b (last 1049) goes out when the first is due: b.
    assert not throttle.ready(['a', 'b'], 1098)
    assert throttle.ready(['a', 'b'], 1099)
    assert not throttle.ready(['a'], 1100)          # both were published at 1099
    # Time going backwards (a restarted simulation) starts over.
    assert throttle.ready(['a'], 10)
    assert not throttle.ready(['a'], 20)
    assert throttle.ready(['b'], 20)                # b's old time was forgotten
    with pytest.raises(ValueError):
        PublishThrottle(-1)
