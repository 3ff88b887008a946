"""
Wheel odometry from free-running encoder counters (pure, no ROS).

Input samples carry the board's sample counter, the board clock in microseconds and
four 32-bit tick counters (FL, FR, RL, RR). Counters wrap: differences are taken
modulo 2^32, so a wrap is an ordinary step. Because counters are absolute, a lost
sample loses no distance: the next sample covers the gap. Duplicated or older
samples are dropped, a board reset (counter and clock jumping back) re-baselines
without moving the pose, and a physically impossible jump is rejected as a glitch.

Outputs: wheel angles (rad) and velocities (rad/s, over a short window to beat count
quantisation) and the base pose (x, y m; yaw rad) and twist in the odom frame,
integrated exactly for a constant twist per step (REP-103, REP-105).
"""

from collections import deque
from dataclasses import dataclass
import math
from typing import Deque, Optional, Sequence, Tuple

from mecanum_control.angles import wrap_angle
from mecanum_control.kinematics import forward_kinematics, integrate_pose, MecanumGeometry

U32 = 1 << 32
#: A sequence or clock jump further back than this is a board reset, not a stale sample.
RESET_BACKWARDS_SAMPLES = 1000
#: Longest time over which wheel travel is bounded by the wheel speed limit (s).
MOTION_WINDOW_S = 1.0


def wrapped_delta(previous: int, current: int, modulus: int = U32) -> int:
    """Signed difference current - previous of counters wrapping at modulus."""
    half = modulus // 2
    return (int(current) - int(previous) + half) % modulus - half


@dataclass(frozen=True)
class EncoderSample:
    """One encoder report: board sample counter, board clock (us) and tick counters."""

    sequence: int
    board_time_us: int
    ticks: Tuple[int, int, int, int]


@dataclass(frozen=True)
class SampleResult:
    """What happened to a sample: status and how many samples were lost before it."""

    status: str  # 'first', 'ok', 'gap', 'duplicate', 'stale', 'reset', 'glitch'
    lost: int = 0
    detail: str = ''

    @property
    def accepted(self) -> bool:
        """Tell whether the sample moved the odometry forward."""
        return self.status in ('ok', 'gap')


class WheelOdometry:
    """Integrates encoder samples into wheel states and a planar pose."""

    def __init__(self, geometry: MecanumGeometry, rad_per_count: float,
                 max_wheel_speed_rad_s: float, velocity_window_s: float = 0.06,
                 glitch_margin_counts: int = 8):
        if not (rad_per_count > 0 and max_wheel_speed_rad_s > 0 and velocity_window_s >= 0):
            raise ValueError('rad_per_count and max_wheel_speed_rad_s must be > 0, '
                             'velocity_window_s >= 0')
        self.geometry = geometry
        self.rad_per_count = rad_per_count
        self.max_wheel_speed_rad_s = max_wheel_speed_rad_s
        self.velocity_window_s = velocity_window_s
        self.glitch_margin_counts = glitch_margin_counts
        self.pose = (0.0, 0.0, 0.0)
        self.twist = (0.0, 0.0, 0.0)
        self.wheel_positions_rad = [0.0] * 4
        self.wheel_velocities_rad_s = [0.0] * 4
        self.lost_samples = 0
        self.rejected_samples = 0
        self.resets = 0
        self._last: Optional[EncoderSample] = None
        self._time_s = 0.0  # unwrapped board time since the first sample
        self._history: Deque[Tuple[float, Tuple[float, ...]]] = deque()

    def update(self, sample: EncoderSample) -> SampleResult:
        """Take one sample; return what was done with it."""
        if len(sample.ticks) != 4:
            raise ValueError(f'expected 4 tick counters, got {len(sample.ticks)}')
        last = self._last
        if last is None:
            self._rebaseline(sample)
            return SampleResult('first')
        seq_step = wrapped_delta(last.sequence, sample.sequence)
        dt_us = wrapped_delta(last.board_time_us, sample.board_time_us)
        if seq_step == 0:
            self.rejected_samples += 1
            return SampleResult('duplicate', detail=f'sequence {sample.sequence} repeated')
        # The clock alone decides too: hardware_interface keeps its sequence counting on
        # across a board restart, so only the clock goes back.
        if seq_step < -RESET_BACKWARDS_SAMPLES or dt_us < -1_000_000:
            self.resets += 1
            self._rebaseline(sample)
            return SampleResult('reset', detail=f'board restarted (sequence {last.sequence} '
                                f'-> {sample.sequence})')
        if seq_step < 0 or dt_us <= 0:
            self.rejected_samples += 1
            return SampleResult('stale', detail=f'sequence {sample.sequence} after '
                                f'{last.sequence}, board clock step {dt_us} us')
        dt_s = dt_us * 1e-6
        deltas = [wrapped_delta(a, b) for a, b in zip(last.ticks, sample.ticks)]
        # Plausible travel: twice the wheel speed limit over the step, but over at most
        # MOTION_WINDOW_S: a link gap longer than that means the board stopped the motors
        # by its command timeout, and a board restarted after a long uptime (its clock
        # wrapped, so the clock seems to jump forward) is caught as a glitch.
        limit = (self.max_wheel_speed_rad_s * 2.0 * min(dt_s, MOTION_WINDOW_S)
                 / self.rad_per_count + self.glitch_margin_counts)
        worst = max(abs(d) for d in deltas)
        if worst > limit:
            self.rejected_samples += 1
            self._rebaseline(sample, keep_state=True)
            return SampleResult('glitch', detail=f'{worst} counts in {dt_s * 1e3:.1f} ms is '
                                f'beyond twice the wheel speed limit; re-baselined')
        lost = seq_step - 1
        self.lost_samples += lost
        self._last = sample
        self._time_s += dt_s
        steps = [d * self.rad_per_count for d in deltas]
        self.wheel_positions_rad = [p + s for p, s in zip(self.wheel_positions_rad, steps)]
        step_twist = forward_kinematics(self.geometry, [s / dt_s for s in steps])
        x, y, yaw = integrate_pose(*self.pose, *step_twist, dt_s)
        self.pose = (x, y, wrap_angle(yaw))
        self._update_velocities(step_twist)
        return SampleResult('gap' if lost else 'ok', lost=lost)

    def _update_velocities(self, step_twist: Sequence[float]) -> None:
        now = self._time_s
        self._history.append((now, tuple(self.wheel_positions_rad)))
        while len(self._history) > 2 and now - self._history[1][0] >= self.velocity_window_s:
            self._history.popleft()
        then, positions = self._history[0]
        if now - then > 0:
            self.wheel_velocities_rad_s = [
                (p - q) / (now - then) for p, q in zip(self.wheel_positions_rad, positions)]
            self.twist = forward_kinematics(self.geometry, self.wheel_velocities_rad_s)
        else:
            self.twist = tuple(step_twist)

    def _rebaseline(self, sample: EncoderSample, keep_state: bool = False) -> None:
        """Restart differencing at sample without moving wheels or pose."""
        self._last = sample
        self._history.clear()
        self._history.append((self._time_s, tuple(self.wheel_positions_rad)))
        if not keep_state:
            self.wheel_velocities_rad_s = [0.0] * 4
            self.twist = (0.0, 0.0, 0.0)

    def reset_pose(self, x: float = 0.0, y: float = 0.0, yaw: float = 0.0) -> None:
        """Set the odom pose (e.g. on a reset request); wheels keep counting."""
        if not all(math.isfinite(v) for v in (x, y, yaw)):
            raise ValueError('pose must be finite')
        self.pose = (x, y, wrap_angle(yaw))
