"""Hand-worked tests of TransformBuffer.oldest_link: how old a looked-up pose is."""

import math

from mecanum_localization.transforms import PlanarTransform, TransformBuffer, TransformError
import pytest


def at(x=0.0, y=0.0, yaw=0.0):
    return PlanarTransform(x, y, yaw)


def test_the_pose_is_as_old_as_its_oldest_timed_link():
    frames = TransformBuffer()
    frames.set_transform('odom', 'base_link', at(1.0), 10.0)
    with pytest.raises(TransformError):   # no map -> odom yet
        frames.oldest_link('map', 'base_link')
    # amcl's map -> odom is future-dated (transform_tolerance): odom -> base_link is older.
    frames.set_transform('map', 'odom', at(y=2.0), 10.5)
    assert frames.oldest_link('map', 'base_link') == (10.0, 'odom -> base_link')
    frames.set_transform('odom', 'base_link', at(1.5), 10.25)
    assert frames.oldest_link('map', 'base_link') == (10.25, 'odom -> base_link')
    # An older transform arriving late does not make the pose older.
    frames.set_transform('odom', 'base_link', at(1.0), 9.0)
    assert frames.oldest_link('map', 'base_link') == (10.25, 'odom -> base_link')
    # Once odom -> base_link is newer than amcl's stamp, map -> odom is the oldest.
    frames.set_transform('odom', 'base_link', at(1.5), 10.75)
    assert frames.oldest_link('map', 'base_link') == (10.5, 'map -> odom')
    # Either direction counts the same links.
    assert frames.oldest_link('base_link', 'map') == (10.5, 'map -> odom')
    pose = frames.lookup('map', 'base_link')
    assert (pose.x, pose.y) == pytest.approx((1.5, 2.0))


def test_static_links_never_age():
    frames = TransformBuffer()
    frames.set_transform('base_link', 'laser', at(0.05), 0.0, static=True)
    assert frames.oldest_link('base_link', 'laser') is None
    assert frames.oldest_link('map', 'map') is None
    frames.set_transform('odom', 'base_link', at(), 3.0)
    assert frames.oldest_link('odom', 'laser') == (3.0, 'odom -> base_link')
    assert frames.oldest_link('laser', 'odom')[0] == 3.0
    assert math.isfinite(frames.oldest_link('odom', 'laser')[0])
