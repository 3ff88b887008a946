"""
amcl's saved state, for a respawned amcl to resume where the last one was (pure, no ROS).

ROS 1 amcl saved its pose every ``save_pose_rate`` and started again from it. Here amcl
saves the global -> odom transform of its latest filter update instead (with the
odometry pose and the estimate's covariance of that update): that transform changes only
as fast as the odometry drifts, so a new amcl resumes at

    pose = saved map -> odom * current odom -> base_link,

right wherever the robot went while amcl was dead, up to the drift of that travel. The
covariance is the saved one widened by the motion model's noise for the odometry change
since the save (:func:`resume`).

The file (``pose_state_file``) is a small YAML document, replaced atomically (a temporary
file in the same folder, then os.replace: a reader sees the old or the new file, whole)::

    # amcl pose state ...
    format: mecanum_amcl_pose_state/1
    stamp: 12.5                 # ROS time (s) of the filter update (its scan's stamp)
    global_frame_id: map
    odom_frame_id: odom
    map_to_odom: [1.0, 2.0, 1.5707963267948966]   # x, y (m), yaw (rad)
    odom_pose: [0.5, 0.0, 0.0]  # odom -> base_link at that update
    covariance:                 # of the estimate: x, y, yaw (m^2, rad^2)
    - [0.01, 0.005, 0.0]
    - [0.005, 0.04, 0.0]
    - [0.0, 0.0, 0.0025]

Anything else (a file cut short, a wrong key, a NaN, a covariance that is not one) is a
:class:`PoseStateError` naming what is wrong.
"""

from dataclasses import dataclass
import math
import numbers
import os
from pathlib import Path
from typing import Optional, Sequence, Tuple

from mecanum_control.angles import wrap_angle
from mecanum_localization.transforms import PlanarTransform
import numpy as np
import yaml

Pose2D = Tuple[float, float, float]
Matrix3 = Tuple[Tuple[float, float, float], Tuple[float, float, float],
                Tuple[float, float, float]]

FORMAT = 'mecanum_amcl_pose_state/1'
#: The resumed cloud is at least this wide (standard deviations): the saved map -> odom
#: is up to save_pose_period_s older than the dead amcl's last correction, and a cloud
#: of one point could not take the first scans' corrections.
MIN_RESUME_STD_XY_M = 0.02
MIN_RESUME_STD_YAW_RAD = 0.02
_KEYS = ('format', 'stamp', 'global_frame_id', 'odom_frame_id', 'map_to_odom', 'odom_pose',
         'covariance')
_HEADER = ('# amcl pose state (mecanum_navigation amcl, parameter pose_state_file): a '
           'respawned amcl\n# of the same launch resumes at map_to_odom * its current '
           'odometry. Rewritten as a whole.\n')


class PoseStateError(ValueError):
    """A pose state file or value is unusable (the message says why)."""


def _is_number(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool) \
        and math.isfinite(value)


def _pose(value, name: str) -> Pose2D:
    if not isinstance(value, (list, tuple)) or len(value) != 3 \
            or not all(_is_number(v) for v in value):
        raise PoseStateError(f'{name} must be 3 finite numbers (x, y, yaw), got {value!r}')
    return tuple(float(v) for v in value)


def _covariance(value) -> Matrix3:
    if not isinstance(value, (list, tuple)) or len(value) != 3 or not all(
            isinstance(row, (list, tuple)) and len(row) == 3 and all(_is_number(v) for v in row)
            for row in value):
        raise PoseStateError(f'covariance must be a 3x3 matrix of finite numbers (x, y, yaw), '
                             f'got {value!r}')
    matrix = np.array(value, dtype=float)
    scale = max(1.0, float(np.abs(matrix).max()))
    if not np.allclose(matrix, matrix.T, rtol=0.0, atol=1e-9 * scale):
        raise PoseStateError(f'covariance must be symmetric, got {value!r}')
    if np.linalg.eigvalsh(matrix).min() < -1e-9 * scale:
        raise PoseStateError(f'covariance must be positive semi-definite, got {value!r}')
    return tuple(tuple(float(v) for v in row) for row in value)


def _frame(value, name: str) -> str:
    if not isinstance(value, str) or not value.strip('/'):
        raise PoseStateError(f'{name} must be a non-empty frame name, got {value!r}')
    return value


@dataclass(frozen=True)
class PoseState:
    """
    What amcl saves: its latest filter update as global -> odom (validated when made).

    ``stamp_s``: ROS time (s) of that update (its scan's stamp); ``map_to_odom``: the
    global -> odom transform then; ``odom_pose``: odom -> base_link then; ``covariance``:
    the estimate's 3x3 covariance (x, y, yaw; m^2, rad^2), in the global frame.
    """

    stamp_s: float
    global_frame: str
    odom_frame: str
    map_to_odom: Pose2D
    odom_pose: Pose2D
    covariance: Matrix3

    def __post_init__(self):
        """Check every field; raise PoseStateError naming the wrong one."""
        if not (_is_number(self.stamp_s) and self.stamp_s >= 0.0):
            raise PoseStateError(f'stamp must be a finite number >= 0 (ROS time, s), got '
                                 f'{self.stamp_s!r}')
        object.__setattr__(self, 'stamp_s', float(self.stamp_s))
        object.__setattr__(self, 'global_frame', _frame(self.global_frame, 'global_frame_id'))
        object.__setattr__(self, 'odom_frame', _frame(self.odom_frame, 'odom_frame_id'))
        object.__setattr__(self, 'map_to_odom', _pose(self.map_to_odom, 'map_to_odom'))
        object.__setattr__(self, 'odom_pose', _pose(self.odom_pose, 'odom_pose'))
        object.__setattr__(self, 'covariance', _covariance(self.covariance))

    def check_frames(self, global_frame: str, odom_frame: str) -> None:
        """Raise PoseStateError unless the state was saved for these frames."""
        if (self.global_frame, self.odom_frame) != (global_frame, odom_frame):
            raise PoseStateError(
                f'saved for frames {self.global_frame!r} -> {self.odom_frame!r}, this amcl '
                f'uses {global_frame!r} -> {odom_frame!r}')


def state_from_estimate(stamp_s: float, global_frame: str, odom_frame: str,
                        pose: Sequence[float], covariance, odom_pose: Sequence[float]
                        ) -> PoseState:
    """Return the state of a filter update: estimate pose at odometry odom_pose."""
    odom = PlanarTransform(*(float(v) for v in odom_pose))
    map_to_odom = PlanarTransform(*(float(v) for v in pose)).compose(odom.inverse())
    return PoseState(float(stamp_s), global_frame, odom_frame,
                     (map_to_odom.x, map_to_odom.y, map_to_odom.yaw),
                     (odom.x, odom.y, odom.yaw),
                     np.asarray(covariance, dtype=float).tolist())


@dataclass(frozen=True)
class Resumed:
    """Where a new filter starts: pose (global frame), 3x3 covariance, odometry since."""

    pose: Pose2D
    covariance: np.ndarray
    travelled_m: float
    turned_rad: float


def resume(state: PoseState, odom_pose: Sequence[float], config) -> Resumed:
    """
    Return the pose and covariance to start a filter from, at odometry odom_pose now.

    pose = state.map_to_odom * odom_pose. The odometry moved d = |(dx, dy)| m and turned
    r = |dyaw| rad (wrapped) since the save; the variances grow by the motion model's
    (config's alpha1..alpha5, nav2's OmniMotionModel) for that change in one step: x and
    y each by max(alpha3, alpha5) d^2 + alpha4 r^2 (along or across the travel, the
    larger, as its direction in the map does not matter), yaw by alpha1 r^2 + alpha2 d^2.
    This is what the filter itself would add for that move without a scan; a path that
    came back (d smaller than the distance driven) is counted by its net change only.
    Then each standard deviation is raised to MIN_RESUME_STD_XY_M / _YAW_RAD if smaller.
    """
    odom = PlanarTransform(*(float(v) for v in odom_pose))
    if not all(math.isfinite(v) for v in (odom.x, odom.y, odom.yaw)):
        raise PoseStateError(f'odometry pose must be 3 finite numbers, got {odom_pose!r}')
    pose = PlanarTransform(*state.map_to_odom).compose(odom)
    saved = state.odom_pose
    d = math.hypot(odom.x - saved[0], odom.y - saved[1])
    r = abs(wrap_angle(odom.yaw - saved[2]))
    covariance = np.array(state.covariance, dtype=float)
    var_xy = max(config.alpha3, config.alpha5) * d * d + config.alpha4 * r * r
    var_yaw = config.alpha1 * r * r + config.alpha2 * d * d
    for index, added, floor in ((0, var_xy, MIN_RESUME_STD_XY_M),
                                (1, var_xy, MIN_RESUME_STD_XY_M),
                                (2, var_yaw, MIN_RESUME_STD_YAW_RAD)):
        covariance[index, index] = max(covariance[index, index] + added, floor * floor)
    return Resumed((pose.x, pose.y, pose.yaw), covariance, d, r)


def save_due(last_saved_s: Optional[float], stamp_s: float, period_s: float) -> bool:
    """
    Tell whether an update stamped stamp_s (ROS time) is to be saved.

    Yes when nothing was saved yet (None), when period_s has passed since the last save,
    or when time went back (a simulation started again).
    """
    return last_saved_s is None or not 0.0 <= stamp_s - last_saved_s < period_s


def to_text(state: PoseState) -> str:
    """Return the file's text for a state."""
    document = {'format': FORMAT, 'stamp': state.stamp_s,
                'global_frame_id': state.global_frame, 'odom_frame_id': state.odom_frame,
                'map_to_odom': list(state.map_to_odom), 'odom_pose': list(state.odom_pose),
                'covariance': [list(row) for row in state.covariance]}
    # safe_dump writes floats PyYAML reads back as floats (1e-05 as 1.0e-05).
    return _HEADER + yaml.safe_dump(document, sort_keys=False, default_flow_style=None,
                                    width=1 << 16)


def from_text(text: str) -> PoseState:
    """Return the state in a file's text; PoseStateError when it is not a valid one."""
    if not text.strip():
        raise PoseStateError('the file is empty')
    try:
        document = yaml.safe_load(text)
    except yaml.YAMLError as error:
        mark = getattr(error, 'problem_mark', None)
        where = f' at line {mark.line + 1}, column {mark.column + 1}' if mark else ''
        problem = getattr(error, 'problem', None) or ' '.join(str(error).split())
        raise PoseStateError(f'not valid YAML: {problem}{where}') from None
    if not isinstance(document, dict):
        raise PoseStateError(f'not a mapping of {", ".join(_KEYS)}')
    if document.get('format') != FORMAT:
        raise PoseStateError(f'not an amcl pose state (format: {FORMAT} expected, got '
                             f'{document.get("format")!r})')
    missing = [key for key in _KEYS if key not in document]
    if missing:
        raise PoseStateError(f'missing {", ".join(missing)}')
    unknown = sorted(str(key) for key in document if key not in _KEYS)
    if unknown:
        raise PoseStateError(f'unknown key(s) {", ".join(unknown)}')
    return PoseState(document['stamp'], document['global_frame_id'],
                     document['odom_frame_id'], document['map_to_odom'],
                     document['odom_pose'], document['covariance'])


def save(path, state: PoseState) -> None:
    """
    Write the state to path atomically: a temporary file beside it, then os.replace.

    Raises OSError (the temporary file removed). Not fsync'ed: the file has to outlive a
    killed amcl, not a power cut (which ends the launch it belongs to anyway).
    """
    path = Path(path)
    temporary = path.with_name(f'.{path.name}.{os.getpid()}.tmp')
    try:
        temporary.write_text(to_text(state))
        os.replace(temporary, path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise


def load(path) -> Optional[PoseState]:
    """Return the state saved in path, None without a file; PoseStateError if unusable."""
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        return None
    except (OSError, UnicodeDecodeError) as error:
        raise PoseStateError(f'cannot read it: {error}') from None
    return from_text(text)
