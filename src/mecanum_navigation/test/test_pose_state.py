"""
Tests of mecanum_navigation.amcl.pose_state (amcl's saved state, to resume from), no ROS.

The resume cases are worked out by hand with config/amcl.yaml's alphas (alpha1 0.1,
alpha2 0.05, alpha3 0.1, alpha4 0.05, alpha5 0.15).
"""

import math
import os
from pathlib import Path

from mecanum_navigation.amcl.particle_filter import AmclConfig
from mecanum_navigation.amcl.pose_state import (
    load, MIN_RESUME_STD_XY_M, MIN_RESUME_STD_YAW_RAD, PoseState, PoseStateError, resume,
    save, save_due, state_from_estimate, to_text)
import numpy as np
import pytest
import yaml

PACKAGE = Path(__file__).resolve().parents[1]
AMCL_PARAMS = yaml.safe_load((PACKAGE / 'config/amcl.yaml').read_text())['amcl'][
    'ros__parameters']
TUNED = AmclConfig(**{key: value for key, value in AMCL_PARAMS.items()
                      if key in AmclConfig.__dataclass_fields__})
COVARIANCE = ((0.01, 0.005, 0.0), (0.005, 0.04, 0.0), (0.0, 0.0, 0.0025))
STATE = PoseState(stamp_s=12.5, global_frame='map', odom_frame='odom',
                  map_to_odom=(1.0, 2.0, math.pi / 2), odom_pose=(0.5, 0.0, 0.0),
                  covariance=COVARIANCE)


def test_the_tuned_alphas_are_the_ones_worked_by_hand():
    assert (TUNED.alpha1, TUNED.alpha2, TUNED.alpha3, TUNED.alpha4, TUNED.alpha5) == (
        0.1, 0.05, 0.1, 0.05, 0.15)


def test_resume_composes_the_saved_map_to_odom_with_the_current_odometry():
    """
    Saved map -> odom (1, 2, 90 deg) with odom -> base_link now (1.1, 0.8, 0.5 rad).

    x = 1 + cos 90 * 1.1 - sin 90 * 0.8 = 0.2, y = 2 + sin 90 * 1.1 + cos 90 * 0.8 = 3.1,
    yaw = pi/2 + 0.5. Since the save (odometry (0.5, 0, 0)) the robot moved (0.6, 0.8):
    1 m, and turned 0.5 rad. Added variances: x and y max(alpha3, alpha5) * 1^2 +
    alpha4 * 0.5^2 = 0.15 + 0.0125 = 0.1625 m^2; yaw alpha1 * 0.5^2 + alpha2 * 1^2 =
    0.025 + 0.05 = 0.075 rad^2. The cross terms stay.
    """
    resumed = resume(STATE, (1.1, 0.8, 0.5), TUNED)
    assert resumed.pose == pytest.approx((0.2, 3.1, math.pi / 2 + 0.5))
    assert resumed.travelled_m == pytest.approx(1.0)
    assert resumed.turned_rad == pytest.approx(0.5)
    np.testing.assert_allclose(resumed.covariance, [[0.1725, 0.005, 0.0],
                                                    [0.005, 0.2025, 0.0],
                                                    [0.0, 0.0, 0.0775]], atol=1e-12)


def test_resume_without_motion_keeps_the_saved_covariance_above_the_floor():
    """Not moved: the pose is map -> odom * the saved odometry, the covariance as saved."""
    resumed = resume(STATE, STATE.odom_pose, TUNED)
    assert resumed.pose == pytest.approx((1.0, 2.5, math.pi / 2))   # (1, 2) + R90 (0.5, 0)
    assert resumed.travelled_m == 0.0 and resumed.turned_rad == 0.0
    np.testing.assert_allclose(resumed.covariance, COVARIANCE, atol=1e-12)


def test_a_collapsed_saved_cloud_is_widened_to_the_floor():
    """A zero covariance, not moved: the floors' variances on the diagonal."""
    state = PoseState(1.0, 'map', 'odom', (0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                      ((0.0,) * 3,) * 3)
    resumed = resume(state, (0.0, 0.0, 0.0), TUNED)
    np.testing.assert_allclose(resumed.covariance, np.diag(
        [MIN_RESUME_STD_XY_M ** 2, MIN_RESUME_STD_XY_M ** 2, MIN_RESUME_STD_YAW_RAD ** 2]))


def test_turning_through_minus_pi_counts_the_short_way():
    """Yaw 3.1 -> -3.1 rad is a turn of 2 pi - 6.2 = 0.0832 rad, not 6.2 rad."""
    state = PoseState(1.0, 'map', 'odom', (0.0, 0.0, 0.0), (0.0, 0.0, 3.1), COVARIANCE)
    assert resume(state, (0.0, 0.0, -3.1), TUNED).turned_rad == pytest.approx(
        2 * math.pi - 6.2)


def test_state_from_estimate_is_the_inverse_of_resume():
    """Estimate (0.2, 3.1, pi/2 + 0.5) at odometry (1.1, 0.8, 0.5): map -> odom (1, 2, pi/2)."""
    state = state_from_estimate(3.0, 'map', 'odom', (0.2, 3.1, math.pi / 2 + 0.5),
                                np.array(COVARIANCE), (1.1, 0.8, 0.5))
    assert state.map_to_odom == pytest.approx((1.0, 2.0, math.pi / 2))
    assert state.odom_pose == (1.1, 0.8, 0.5) and state.stamp_s == 3.0
    assert state.covariance == COVARIANCE
    assert all(type(v) is float for v in (*state.map_to_odom, *state.odom_pose,
                                          *(v for row in state.covariance for v in row)))


@pytest.mark.parametrize('last_saved_s, stamp_s, due', [
    (None, 5.0, True),        # never saved: at once
    (5.0, 6.9, False),        # 1.9 s of a 2 s period
    (5.0, 7.0, True),         # the period is over
    (5.0, 5.0, False),        # the same update
    (5.0, 4.0, True),         # time went back (a simulation restarted): save anew
])
def test_save_due_every_period_of_ros_time(last_saved_s, stamp_s, due):
    assert save_due(last_saved_s, stamp_s, 2.0) is due


def test_save_then_load_gives_the_same_state_in_a_small_readable_file(tmp_path):
    path = tmp_path / 'amcl_pose.yaml'
    save(path, STATE)
    text = path.read_text()
    assert len(text) < 1000
    assert text.startswith('#')                    # says what it is
    document = yaml.safe_load(text)
    assert document['map_to_odom'] == [1.0, 2.0, math.pi / 2]
    assert load(path) == STATE
    assert sorted(p.name for p in tmp_path.iterdir()) == ['amcl_pose.yaml']  # no temp file


def test_tiny_and_huge_numbers_survive_the_yaml(tmp_path):
    """Write YAML floats: PyYAML reads 1e-05 (no point) back as text."""
    covariance = ((1e-05, 0.0, 0.0), (0.0, 1e-05, 0.0), (0.0, 0.0, 1e-07))
    state = PoseState(1e9, 'map', 'odom', (1e-06, -2e-07, 0.0), (0.0, 0.0, 0.0), covariance)
    path = tmp_path / 'state.yaml'
    save(path, state)
    assert load(path) == state


def test_save_replaces_the_file_atomically(tmp_path, monkeypatch):
    """A save that fails before the rename leaves the previous file whole and no temp."""
    path = tmp_path / 'amcl_pose.yaml'
    save(path, STATE)

    def no_rename(source, target):
        raise OSError('disk full')
    monkeypatch.setattr(os, 'replace', no_rename)
    with pytest.raises(OSError, match='disk full'):
        save(path, PoseState(99.0, 'map', 'odom', (0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                             COVARIANCE))
    monkeypatch.undo()
    assert load(path) == STATE
    assert sorted(p.name for p in tmp_path.iterdir()) == ['amcl_pose.yaml']


def test_load_without_a_file_is_none(tmp_path):
    assert load(tmp_path / 'none.yaml') is None


def _valid_document() -> dict:
    return yaml.safe_load(to_text(STATE))


def _with(**changes) -> str:
    document = _valid_document()
    for key, value in changes.items():
        if value is None:
            del document[key]
        else:
            document[key] = value
    return yaml.safe_dump(document)


@pytest.mark.parametrize('text, message', [
    ('', 'is empty'),
    ('map_to_odom: [1.0, 2.0', 'not valid YAML'),
    ('- 1\n- 2\n', 'not a mapping'),
    (_with(format='something else'), 'not an amcl pose state'),
    (_with(stamp=None), 'missing stamp'),
    (_with(extra=1), 'unknown key(s) extra'),
    (_with(stamp='noon'), 'stamp must be a finite number >= 0'),
    (_with(stamp=-1.0), 'stamp must be a finite number >= 0'),
    (_with(global_frame_id=''), 'global_frame_id must be a non-empty frame name'),
    (_with(map_to_odom=[1.0, float('nan'), 0.0]), 'map_to_odom must be 3 finite numbers'),
    (_with(odom_pose=[1.0, 2.0]), 'odom_pose must be 3 finite numbers'),
    (_with(odom_pose=[True, 2.0, 0.0]), 'odom_pose must be 3 finite numbers'),
    (_with(covariance=[[1.0, 0.0], [0.0, 1.0]]), 'covariance must be a 3x3 matrix'),
    (_with(covariance=[[0.01, 0.005, 0.0], [0.0, 0.04, 0.0], [0.0, 0.0, 0.0025]]),
     'covariance must be symmetric'),
    (_with(covariance=[[-0.01, 0.0, 0.0], [0.0, 0.04, 0.0], [0.0, 0.0, 0.0025]]),
     'covariance must be positive semi-definite'),
    (to_text(STATE)[:len(to_text(STATE)) // 2], ''),    # cut short by a crash
], ids=['empty', 'bad_yaml', 'list', 'format', 'no_stamp', 'extra_key', 'text_stamp',
        'negative_stamp', 'empty_frame', 'nan_pose', 'short_pose', 'bool_in_pose',
        '2x2_covariance', 'asymmetric', 'negative_variance', 'truncated'])
def test_a_corrupt_file_is_a_clear_error(tmp_path, text, message):
    path = tmp_path / 'amcl_pose.yaml'
    path.write_text(text)
    with pytest.raises(PoseStateError) as error:
        load(path)
    assert message in str(error.value)
    assert '\n' not in str(error.value)                # one log line


def test_an_unreadable_file_is_a_clear_error(tmp_path):
    path = tmp_path / 'a_folder.yaml'
    path.mkdir()
    with pytest.raises(PoseStateError, match='cannot read'):
        load(path)


def test_the_frames_must_be_the_nodes():
    STATE.check_frames('map', 'odom')
    with pytest.raises(PoseStateError, match="saved for frames 'map' -> 'odom', this amcl "
                                             "uses 'world' -> 'odom'"):
        STATE.check_frames('world', 'odom')


def test_a_state_is_validated_when_made():
    with pytest.raises(PoseStateError, match='covariance must be symmetric'):
        PoseState(1.0, 'map', 'odom', (0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                  ((1.0, 0.5, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)))
