"""
Planar extended Kalman filter of a mecanum robot (pure: numpy, no ROS).

State (8, SI units, REP-103/105), as robot_localization's state restricted to the plane:
``[x, y, yaw, vx, vy, vyaw, ax, ay]``: the pose of base_link in the world frame (odom or
map; x, y in m, yaw in rad wrapped to [-pi, pi)) and the body velocities (m/s, rad/s)
and accelerations (m/s^2) in base_link.

Motion model: omnidirectional constant acceleration (robot_localization's, in 2D)::

    x    += (vx c - vy s) dt + (ax c - ay s) dt^2 / 2      c = cos(yaw), s = sin(yaw)
    y    += (vx s + vy c) dt + (ax s + ay c) dt^2 / 2
    yaw  += vyaw dt
    vx   += ax dt,  vy += ay dt;  vyaw, ax, ay constant

with covariance ``P = F P F' + Q dt`` (F the Jacobian; the process noise Q is per second).

Measurements fuse any subset of the state (indices + values + covariance), with the yaw
innovation wrapped, an optional Mahalanobis gate and the Joseph-form update. The algebra
(prediction, Cholesky of the innovation covariance, gain, update) is written out in
numba-compiled loops: numpy's per-call overhead on 8x8 matrices made a measurement cost
about 0.3 ms, which the control process paid 150 times a simulated second. The first
measurement after a reset initialises the variables it measures directly (values and
covariance), as robot_localization does. Measurements older than the filter are either
dropped or, with ``smooth_lagged_data``, fused by rewinding to the last state before them
and re-applying every later measurement in stamp order (within ``history_length_s``).
"""

from collections import deque
from dataclasses import dataclass
import math
from typing import Deque, List, Optional, Sequence

from mecanum_control.angles import wrap_angle
from numba import njit
import numpy as np

STATE_SIZE = 8
X, Y, YAW, VX, VY, VYAW, AX, AY = range(STATE_SIZE)
STATE_NAMES = ('x', 'y', 'yaw', 'vx', 'vy', 'vyaw', 'ax', 'ay')
#: Smallest variance a measurement may claim (robot_localization's floor).
MIN_VARIANCE = 1e-9


#: Kernel status codes of :func:`_correct_kernel`.
_FUSED, _SINGULAR, _GATED = 0, 1, 2

#: mecanum_control.angles.wrap_angle compiled for the kernels: [-pi, pi), one definition.
#: (numba's cache of a kernel calling it is not invalidated by an edit of angles.py.)
_wrap = njit(cache=True)(wrap_angle)


@njit(cache=True)
def predict_state(state: np.ndarray, dt: float) -> np.ndarray:
    """Return the state (float array of 8) moved dt seconds ahead by the model."""
    x, y, yaw, vx, vy = state[X], state[Y], state[YAW], state[VX], state[VY]
    vyaw, ax, ay = state[VYAW], state[AX], state[AY]
    c, s = math.cos(yaw), math.sin(yaw)
    half_dt2 = 0.5 * dt * dt
    predicted = np.empty(STATE_SIZE)
    predicted[X] = x + (vx * c - vy * s) * dt + (ax * c - ay * s) * half_dt2
    predicted[Y] = y + (vx * s + vy * c) * dt + (ax * s + ay * c) * half_dt2
    predicted[YAW] = _wrap(yaw + vyaw * dt)
    predicted[VX] = vx + ax * dt
    predicted[VY] = vy + ay * dt
    predicted[VYAW] = vyaw
    predicted[AX] = ax
    predicted[AY] = ay
    return predicted


@njit(cache=True)
def transition_jacobian(state: np.ndarray, dt: float) -> np.ndarray:
    """Return the Jacobian of :func:`predict_state` with respect to the state."""
    yaw, vx, vy, ax, ay = state[YAW], state[VX], state[VY], state[AX], state[AY]
    c, s = math.cos(yaw), math.sin(yaw)
    half_dt2 = 0.5 * dt * dt
    jacobian = np.eye(STATE_SIZE)
    jacobian[X, YAW] = -(vx * s + vy * c) * dt - (ax * s + ay * c) * half_dt2
    jacobian[X, VX], jacobian[X, VY] = c * dt, -s * dt
    jacobian[X, AX], jacobian[X, AY] = c * half_dt2, -s * half_dt2
    jacobian[Y, YAW] = (vx * c - vy * s) * dt + (ax * c - ay * s) * half_dt2
    jacobian[Y, VX], jacobian[Y, VY] = s * dt, c * dt
    jacobian[Y, AX], jacobian[Y, AY] = s * half_dt2, c * half_dt2
    jacobian[YAW, VYAW] = dt
    jacobian[VX, AX] = dt
    jacobian[VY, AY] = dt
    return jacobian


@njit(cache=True)
def _symmetric_sandwich(left: np.ndarray, middle: np.ndarray) -> np.ndarray:
    """Return left @ middle @ left.T (n x n from n x k and k x k), symmetrised."""
    rows, inner = left.shape
    product = np.zeros((rows, inner))
    for i in range(rows):
        for j in range(inner):
            total = 0.0
            for k in range(inner):
                total += left[i, k] * middle[k, j]
            product[i, j] = total
    result = np.empty((rows, rows))
    for i in range(rows):
        for j in range(i + 1):
            total = 0.0
            for k in range(inner):
                total += product[i, k] * left[j, k]
            result[i, j] = total
    for i in range(rows):
        for j in range(i):
            result[j, i] = result[i, j]
    return result


@njit(cache=True)
def _predict_kernel(state: np.ndarray, covariance: np.ndarray, process_noise: np.ndarray,
                    dt: float):
    """Return the predicted state and covariance ``F P F' + Q dt`` (symmetric)."""
    jacobian = transition_jacobian(state, dt)
    predicted = _symmetric_sandwich(jacobian, covariance)
    for i in range(STATE_SIZE):
        for j in range(STATE_SIZE):
            predicted[i, j] += 0.5 * (process_noise[i, j] + process_noise[j, i]) * dt
    return predict_state(state, dt), predicted


@njit(cache=True)
def _floored(covariance: np.ndarray) -> np.ndarray:
    """Return the covariance symmetrised, with variances below MIN_VARIANCE raised to it."""
    size = covariance.shape[0]
    floored = np.empty((size, size))
    for i in range(size):
        for j in range(size):
            floored[i, j] = 0.5 * (covariance[i, j] + covariance[j, i])
        floored[i, i] = max(floored[i, i], MIN_VARIANCE)
    return floored


@njit(cache=True)
def _cholesky_solve(lower: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """Solve (L L') x = b given the Cholesky factor L."""
    size = vector.shape[0]
    forward = np.empty(size)
    for i in range(size):
        total = vector[i]
        for k in range(i):
            total -= lower[i, k] * forward[k]
        forward[i] = total / lower[i, i]
    solution = np.empty(size)
    for i in range(size - 1, -1, -1):
        total = forward[i]
        for k in range(i + 1, size):
            total -= lower[k, i] * solution[k]
        solution[i] = total / lower[i, i]
    return solution


@njit(cache=True)
def _correct_kernel(state: np.ndarray, covariance: np.ndarray, indices: np.ndarray,
                    values: np.ndarray, noise: np.ndarray, specific_force: bool,
                    threshold: float):
    """
    Correct state and covariance with a measurement of state[indices].

    Return (status, squared Mahalanobis distance, state, covariance): status _FUSED with
    the updated estimate, or _SINGULAR / _GATED with the inputs unchanged. ``noise`` is
    symmetrised and floored at MIN_VARIANCE here.
    """
    size = indices.shape[0]
    floored = _floored(noise)
    # h(x) and its Jacobian H (one row per measured variable).
    observation = np.zeros((size, STATE_SIZE))
    innovation = np.empty(size)
    vx, vy, vyaw = state[VX], state[VY], state[VYAW]
    for row in range(size):
        index = indices[row]
        observation[row, index] = 1.0
        predicted = state[index]
        if specific_force and index == AX:      # ax - vyaw vy
            predicted -= vyaw * vy
            observation[row, VYAW], observation[row, VY] = -vy, -vyaw
        elif specific_force and index == AY:    # ay + vyaw vx
            predicted += vyaw * vx
            observation[row, VYAW], observation[row, VX] = vx, vyaw
        innovation[row] = values[row] - predicted
        if index == YAW:
            innovation[row] = _wrap(innovation[row])
    innovation_covariance = _symmetric_sandwich(observation, covariance) + floored
    lower = np.zeros((size, size))
    for j in range(size):
        pivot = innovation_covariance[j, j]
        for k in range(j):
            pivot -= lower[j, k] * lower[j, k]
        if not pivot > 0.0:   # also NaN
            return _SINGULAR, math.nan, state, covariance
        lower[j, j] = math.sqrt(pivot)
        for i in range(j + 1, size):
            total = innovation_covariance[i, j]
            for k in range(j):
                total -= lower[i, k] * lower[j, k]
            lower[i, j] = total / lower[j, j]
    weighted = _cholesky_solve(lower, innovation)
    squared_distance = 0.0
    for i in range(size):
        squared_distance += innovation[i] * weighted[i]
    if squared_distance >= threshold * threshold:
        return _GATED, squared_distance, state, covariance
    # K = P H' S^-1, a row at a time (S symmetric).
    gain = np.empty((STATE_SIZE, size))
    row_ph = np.empty(size)
    for i in range(STATE_SIZE):
        for r in range(size):
            total = 0.0
            for k in range(STATE_SIZE):
                total += covariance[i, k] * observation[r, k]
            row_ph[r] = total
        gain[i, :] = _cholesky_solve(lower, row_ph)
    updated = state.copy()
    for i in range(STATE_SIZE):
        for r in range(size):
            updated[i] += gain[i, r] * innovation[r]
    updated[YAW] = _wrap(updated[YAW])
    # Joseph form: (I - K H) P (I - K H)' + K R K'.
    complement = np.eye(STATE_SIZE)
    for i in range(STATE_SIZE):
        for j in range(STATE_SIZE):
            for r in range(size):
                complement[i, j] -= gain[i, r] * observation[r, j]
    updated_covariance = _symmetric_sandwich(complement, covariance) + _symmetric_sandwich(
        gain, floored)
    return _FUSED, squared_distance, updated, updated_covariance


class Measurement:
    """
    A measurement of some state variables at a time.

    ``indices`` name the measured variables (0..7, see STATE_NAMES), ``values`` and the
    square ``covariance`` follow that order. ``rejection_threshold`` is the Mahalanobis
    distance (in standard deviations) at or beyond which the measurement is rejected.
    With ``specific_force`` the ax/ay values are what an accelerometer on base_link reads
    (the inertial acceleration, including the rotating frame's terms), so the model is
    ``ax - vyaw vy`` and ``ay + vyaw vx`` instead of ax and ay (the state's accelerations
    are the rates of the BODY-frame velocities, as in robot_localization, which leaves
    these terms out: about 1 m/s^2 for a robot strafing at 0.5 m/s while turning at 2 rad/s).
    Malformed shapes raise ValueError; non-finite numbers are accepted here and rejected
    (with a reason) by :meth:`PlanarEkf.process`.
    """

    __slots__ = ('time_s', 'indices', 'index_array', 'values', 'covariance',
                 'rejection_threshold', 'source', 'specific_force')

    def __init__(self, time_s: float, indices: Sequence[int], values: Sequence[float],
                 covariance, rejection_threshold: float = math.inf, source: str = '',
                 specific_force: bool = False):
        indices = tuple(int(i) for i in indices)
        if not indices or len(set(indices)) != len(indices) or not all(
                0 <= i < STATE_SIZE for i in indices):
            raise ValueError(f'measurement indices must be distinct, in 0..{STATE_SIZE - 1}, '
                             f'got {indices}')
        values = np.array(values, dtype=float).reshape(-1)
        covariance = np.array(covariance, dtype=float)
        size = len(indices)
        if values.shape != (size,) or covariance.shape != (size, size):
            raise ValueError(f'measurement of {size} variables needs {size} values and a '
                             f'{size}x{size} covariance, got {values.shape} and '
                             f'{covariance.shape}')
        if not rejection_threshold > 0:
            raise ValueError(f'rejection_threshold must be > 0, got {rejection_threshold}')
        self.time_s = float(time_s)
        self.indices = indices
        self.index_array = np.array(indices, dtype=np.int64)
        self.values = values
        self.covariance = covariance
        self.rejection_threshold = float(rejection_threshold)
        self.source = source
        self.specific_force = bool(specific_force)

    def __repr__(self) -> str:
        """Return a short description (variables, values, time, source)."""
        names = ', '.join(STATE_NAMES[i] for i in self.indices)
        return (f'Measurement({self.source or "?"} at {self.time_s:.6f} s: {names} = '
                f'{self.values.tolist()})')


@dataclass(frozen=True)
class UpdateResult:
    """
    What :meth:`PlanarEkf.process` did with a measurement.

    status: 'initialized' (first measurement set the variables), 'fused', 'gated'
    (Mahalanobis gate), 'non_finite', 'singular' (innovation covariance not positive
    definite), 'late' (older than the filter, smoothing off) or 'too_old' (older than
    the history). ``replayed`` counts later measurements re-applied after a rewind.
    """

    status: str
    reason: str = ''
    replayed: int = 0

    @property
    def accepted(self) -> bool:
        """Tell whether the measurement changed the estimate."""
        return self.status in ('initialized', 'fused')


@dataclass
class _Snapshot:
    """Filter state at a time, after applying ``measurement`` (None: a base state)."""

    time_s: Optional[float]
    state: np.ndarray
    covariance: np.ndarray
    initialized: bool
    measurement: Optional[Measurement] = None


def _check_matrix(name: str, matrix, allow_zero_diagonal: bool) -> np.ndarray:
    matrix = np.array(matrix, dtype=float)
    if matrix.shape != (STATE_SIZE, STATE_SIZE) or not np.all(np.isfinite(matrix)):
        raise ValueError(f'{name} must be a finite {STATE_SIZE}x{STATE_SIZE} matrix')
    diagonal = np.diag(matrix)
    if np.any(diagonal < 0) or (not allow_zero_diagonal and np.any(diagonal <= 0)):
        sign = 'non-negative' if allow_zero_diagonal else 'positive'
        raise ValueError(f'{name} must have a {sign} diagonal, got {diagonal.tolist()}')
    if not np.allclose(matrix, matrix.T, rtol=1e-9, atol=1e-12):
        raise ValueError(f'{name} must be symmetric')
    return 0.5 * (matrix + matrix.T)


class PlanarEkf:
    """The filter: state, covariance, time, and the history used to fuse late data."""

    def __init__(self, process_noise, initial_covariance,
                 initial_state: Optional[Sequence[float]] = None,
                 smooth_lagged_data: bool = False, history_length_s: float = 0.0):
        self.process_noise = _check_matrix('process_noise', process_noise, True)
        self.initial_covariance = _check_matrix('initial_covariance', initial_covariance,
                                                False)
        state = np.zeros(STATE_SIZE) if initial_state is None else np.array(
            initial_state, dtype=float).reshape(-1)
        if state.shape != (STATE_SIZE,) or not np.all(np.isfinite(state)):
            raise ValueError(f'initial_state must be {STATE_SIZE} finite numbers')
        state[YAW] = wrap_angle(state[YAW])
        self.initial_state = state
        if not (math.isfinite(history_length_s) and history_length_s >= 0):
            raise ValueError(f'history_length_s must be finite and >= 0, got {history_length_s}')
        self.smooth_lagged_data = bool(smooth_lagged_data)
        self.history_length_s = float(history_length_s)
        self.state = state.copy()
        self.covariance = self.initial_covariance.copy()
        self.time_s: Optional[float] = None
        self.initialized = False
        self._base = self._snapshot()
        self._history: Deque[_Snapshot] = deque()

    # -- public API ----------------------------------------------------------------------

    def reset(self) -> None:
        """Forget everything: initial state and covariance, no time, not initialised."""
        self.state = self.initial_state.copy()
        self.covariance = self.initial_covariance.copy()
        self.time_s = None
        self.initialized = False
        self._base = self._snapshot()
        self._history.clear()

    def set_pose(self, time_s: float, x: float, y: float, yaw: float, pose_covariance) -> None:
        """
        Restart at a pose (world frame) with its 3x3 (x, y, yaw) covariance at time_s.

        Velocities and accelerations are zeroed; their covariance is the initial one.
        History is cleared: older measurements are dropped afterwards.
        """
        pose_covariance = np.array(pose_covariance, dtype=float)
        if pose_covariance.shape != (3, 3):
            raise ValueError('set_pose needs a 3x3 covariance of x, y, yaw')
        if not (all(math.isfinite(v) for v in (time_s, x, y, yaw))
                and np.all(np.isfinite(pose_covariance))):
            raise ValueError('set_pose needs a finite time, pose and covariance')
        self.state = np.zeros(STATE_SIZE)
        self.state[[X, Y, YAW]] = (x, y, wrap_angle(yaw))
        self.covariance = self.initial_covariance.copy()
        pose_indices = [X, Y, YAW]
        self.covariance[np.ix_(pose_indices, pose_indices)] = _floored(pose_covariance)
        self.time_s = float(time_s)
        self.initialized = True
        self._base = self._snapshot()
        self._history.clear()

    def predict_to(self, time_s: float) -> None:
        """Predict (no measurement) up to time_s; no-op before initialisation or backwards."""
        if not self.initialized or not math.isfinite(time_s) or time_s <= self.time_s:
            return
        self._predict(time_s - self.time_s)
        self.time_s = float(time_s)
        self._prune()

    def process(self, measurement: Measurement) -> UpdateResult:
        """Fuse one measurement; return what was done with it (the estimate is updated)."""
        problem = _non_finite(measurement)
        if problem:
            return UpdateResult('non_finite', problem)
        if self.time_s is None or measurement.time_s >= self.time_s:
            result = self._apply(measurement)
            self._history.append(self._snapshot(measurement))
            self._prune()
            return result
        lag = self.time_s - measurement.time_s
        if not self.smooth_lagged_data:
            return UpdateResult('late', f'{lag:.3f} s older than the filter '
                                '(smooth_lagged_data is off)')
        if lag > self.history_length_s:
            return UpdateResult('too_old', f'{lag:.3f} s older than the filter, beyond '
                                f'history_length {self.history_length_s} s')
        return self._rewind_and_replay(measurement)

    # -- internals -----------------------------------------------------------------------

    def _snapshot(self, measurement: Optional[Measurement] = None) -> _Snapshot:
        return _Snapshot(self.time_s, self.state.copy(), self.covariance.copy(),
                         self.initialized, measurement)

    def _restore(self, snapshot: _Snapshot) -> None:
        self.time_s = snapshot.time_s
        self.state = snapshot.state.copy()
        self.covariance = snapshot.covariance.copy()
        self.initialized = snapshot.initialized

    def _prune(self) -> None:
        """Keep the snapshots needed to rewind to any time within history_length_s."""
        cutoff = self.time_s - self.history_length_s
        while self._history and self._history[0].time_s < cutoff:
            self._base = self._history.popleft()

    def _rewind_and_replay(self, measurement: Measurement) -> UpdateResult:
        entries = list(self._history)
        # Insert after every measurement with the same or an older stamp (arrival order
        # breaks ties, as in-order processing would).
        position = len(entries)
        while position > 0 and entries[position - 1].time_s > measurement.time_s:
            position -= 1
        start = entries[position - 1] if position > 0 else self._base
        if start.initialized and start.time_s is not None and start.time_s > measurement.time_s:
            return UpdateResult('too_old', 'older than the last reset or the kept history')
        latest_time = self.time_s
        self._restore(start)
        for _ in range(len(entries) - position):
            self._history.pop()
        result = self._apply(measurement)
        self._history.append(self._snapshot(measurement))
        for entry in entries[position:]:
            self._apply(entry.measurement)
            self._history.append(self._snapshot(entry.measurement))
        # Predictions made without measurements (sensor timeout) are not replayed, but the
        # filter never goes back in time.
        if latest_time is not None and self.time_s < latest_time:
            self._predict(latest_time - self.time_s)
            self.time_s = latest_time
        self._prune()
        return UpdateResult(result.status, result.reason, len(entries) - position)

    def _apply(self, measurement: Measurement) -> UpdateResult:
        """Predict to the measurement's time and correct (or initialise) with it."""
        if not self.initialized:
            self._initialize(measurement)
            return UpdateResult('initialized')
        dt = measurement.time_s - self.time_s
        if dt > 0:
            self._predict(dt)
        self.time_s = measurement.time_s
        return self._correct(measurement)

    def _initialize(self, measurement: Measurement) -> None:
        indices = list(measurement.indices)
        self.state[indices] = measurement.values
        if YAW in indices:
            self.state[YAW] = wrap_angle(self.state[YAW])
        self.covariance[np.ix_(indices, indices)] = _floored(measurement.covariance)
        self.time_s = measurement.time_s
        self.initialized = True

    def _predict(self, dt: float) -> None:
        self.state, self.covariance = _predict_kernel(
            self.state, self.covariance, self.process_noise, float(dt))

    def _correct(self, measurement: Measurement) -> UpdateResult:
        status, squared_distance, self.state, self.covariance = _correct_kernel(
            self.state, self.covariance, measurement.index_array, measurement.values,
            measurement.covariance, measurement.specific_force,
            measurement.rejection_threshold)
        if status == _SINGULAR:
            return UpdateResult('singular', 'innovation covariance is not positive definite '
                                '(inconsistent measurement covariance?)')
        if status == _GATED:
            return UpdateResult('gated', f'Mahalanobis distance {math.sqrt(squared_distance):.2f}'
                                f' >= threshold {measurement.rejection_threshold:g}')
        return UpdateResult('fused')


@njit(cache=True)
def _all_finite(array: np.ndarray) -> bool:
    """Tell whether every element of a float array is finite (no NaN or inf)."""
    for value in array.flat:
        if not math.isfinite(value):
            return False
    return True


def _non_finite(measurement: Measurement) -> str:
    """Describe what is not finite in a measurement ('' if everything is)."""
    problems: List[str] = []
    if not math.isfinite(measurement.time_s):
        problems.append('time')
    if not _all_finite(measurement.values):
        problems.append('value')
    if not _all_finite(measurement.covariance):
        problems.append('covariance')
    return f'non-finite {" and ".join(problems)}' if problems else ''
