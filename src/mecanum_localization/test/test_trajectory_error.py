"""Tests of mecanum_localization.trajectory_error with hand-worked cases."""

from dataclasses import astuple
import math

from mecanum_localization.trajectory_error import interpolate_poses, trajectory_error
from mecanum_localization.transforms import PlanarTransform
import numpy as np
import pytest


def test_interpolation_crosses_the_yaw_seam_the_short_way():
    poses = np.array([[0.0, 0.0, math.pi - 0.1], [2.0, 4.0, -math.pi + 0.1]])
    mid = interpolate_poses([0.0, 1.0], poses, [0.5])[0]
    assert mid[:2] == pytest.approx([1.0, 2.0])
    assert abs(abs(mid[2]) - math.pi) < 1e-9  # through pi, not through 0


def test_a_perfect_estimate_in_another_frame_has_no_error():
    times = np.linspace(0.0, 10.0, 101)
    truth = np.column_stack([2.0 + 0.1 * times, 1.0 + 0.05 * times, 0.2 * times])
    # The same motion seen from an odom frame at the start pose (2, 1, 0).
    odom_in_world = PlanarTransform(2.0, 1.0, 0.0)
    estimate = np.array([astuple(odom_in_world.inverse().compose(PlanarTransform(*p)))
                         for p in truth])
    error = trajectory_error(times, truth, times[::2], estimate[::2])
    assert error.samples == 51
    assert error.rms_position_m == pytest.approx(0.0, abs=1e-12)
    assert error.max_yaw_rad == pytest.approx(0.0, abs=1e-12)


def test_a_constant_offset_grown_after_the_start_is_measured():
    times = np.array([0.0, 1.0, 2.0, 3.0])
    truth = np.zeros((4, 3))
    # Agrees at t = 0, then 0.3 m off in y and 0.1 rad off for the three later samples.
    estimate = np.array([[0.0, 0.0, 0.0], [0.0, 0.3, 0.1], [0.0, 0.3, 0.1], [0.0, 0.3, 0.1]])
    error = trajectory_error(times, truth, times, estimate)
    assert error.final_position_m == pytest.approx(0.3)
    assert error.max_position_m == pytest.approx(0.3)
    assert error.rms_position_m == pytest.approx(math.sqrt(3 * 0.09 / 4))
    assert error.final_yaw_rad == pytest.approx(0.1)
    assert error.rms_yaw_rad == pytest.approx(math.sqrt(3 * 0.01 / 4))


def test_samples_outside_the_truth_span_are_left_out_and_bad_input_is_refused():
    times = np.array([1.0, 2.0])
    truth = np.zeros((2, 3))
    error = trajectory_error(times, truth, [0.0, 1.0, 1.5, 3.0], np.zeros((4, 3)))
    assert error.samples == 2
    with pytest.raises(ValueError, match='within the truth'):
        trajectory_error(times, truth, [5.0], np.zeros((1, 3)))
    with pytest.raises(ValueError, match='one time per estimate'):
        trajectory_error(times, truth, [1.0, 2.0], np.zeros((1, 3)))
    with pytest.raises(ValueError, match='at least 2 truth'):
        trajectory_error([1.0], np.zeros((1, 3)), [1.0], np.zeros((1, 3)))
