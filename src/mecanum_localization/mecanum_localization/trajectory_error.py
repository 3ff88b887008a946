"""
Accuracy of an estimated trajectory against ground truth (pure, numpy, no ROS).

Poses are planar (x m, y m, yaw rad). The estimate lives in its own fixed frame
(e.g. ``odom``), the truth in the simulator's ``world``; the two are aligned by the
rigid transform that makes them agree at the estimate's first sample (where the
estimator started), so every later difference is the estimator's drift. Truth is
interpolated linearly at the estimate's time stamps (yaw unwrapped first); estimate
samples outside the truth's time span are left out.
"""

from dataclasses import astuple, dataclass
from typing import Sequence

from mecanum_control.angles import wrap_angles
from mecanum_localization.transforms import PlanarTransform
import numpy as np


def interpolate_poses(times_s: Sequence[float], poses: np.ndarray,
                      query_s: Sequence[float]) -> np.ndarray:
    """Linearly interpolate (N, 3) poses at query times (within the time span)."""
    times = np.asarray(times_s, dtype=float)
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    query = np.asarray(query_s, dtype=float)
    yaw = np.unwrap(poses[:, 2])
    return np.column_stack([np.interp(query, times, poses[:, 0]),
                            np.interp(query, times, poses[:, 1]),
                            wrap_angles(np.interp(query, times, yaw))])


@dataclass(frozen=True)
class TrajectoryError:
    """Position (m) and yaw (rad) errors of an estimate over a run."""

    samples: int
    rms_position_m: float
    max_position_m: float
    final_position_m: float
    rms_yaw_rad: float
    max_yaw_rad: float
    final_yaw_rad: float


def trajectory_error(truth_times_s: Sequence[float], truth_poses: np.ndarray,
                     estimate_times_s: Sequence[float],
                     estimate_poses: np.ndarray) -> TrajectoryError:
    """Compare an estimate with ground truth (see the module docstring for the alignment)."""
    truth_times = np.asarray(truth_times_s, dtype=float)
    estimate_times = np.asarray(estimate_times_s, dtype=float)
    estimate = np.asarray(estimate_poses, dtype=float).reshape(-1, 3)
    if len(truth_times) < 2 or len(truth_times) != len(np.asarray(truth_poses).reshape(-1, 3)):
        raise ValueError('need at least 2 truth samples with one time each')
    if len(estimate_times) != len(estimate):
        raise ValueError('need one time per estimate sample')
    inside = (estimate_times >= truth_times[0]) & (estimate_times <= truth_times[-1])
    if not inside.any():
        raise ValueError('no estimate sample lies within the truth time span')
    estimate_times, estimate = estimate_times[inside], estimate[inside]
    truth = interpolate_poses(truth_times, truth_poses, estimate_times)
    # The rigid transform world <- estimate frame making them agree at the first sample.
    world_from_estimate = PlanarTransform(*truth[0]).compose(
        PlanarTransform(*estimate[0]).inverse())
    aligned = np.array([astuple(world_from_estimate.compose(PlanarTransform(*p)))
                        for p in estimate])
    position = np.hypot(aligned[:, 0] - truth[:, 0], aligned[:, 1] - truth[:, 1])
    yaw = np.abs(wrap_angles(aligned[:, 2] - truth[:, 2]))
    return TrajectoryError(
        samples=len(position),
        rms_position_m=float(np.sqrt(np.mean(position ** 2))),
        max_position_m=float(position.max()), final_position_m=float(position[-1]),
        rms_yaw_rad=float(np.sqrt(np.mean(yaw ** 2))), max_yaw_rad=float(yaw.max()),
        final_yaw_rad=float(yaw[-1]))
